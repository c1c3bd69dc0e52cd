"""``--help`` is plain text: the parser descriptions come from RST module docstrings without their markup."""
from __future__ import annotations

import pytest

from atsvo_ros.tools import demo, events, info, sim
from atsvo_ros.tools._help import description, plain_text


def test_plain_text_removes_literals_and_roles():
    assert plain_text("``atsvo-sim``: see :func:`iter_sequence`") == "atsvo-sim: see iter_sequence"
    assert plain_text(":class:`~atsvo_ros.sim.events.EventModel` and :py:meth:`A.b`") == "EventModel and A.b"
    assert plain_text(":ref:`the guide <guide>`, `default role`, a ``x`b`` literal") == \
        "the guide, default role, a x`b literal"
    assert plain_text("no markup: 2 * 3, 'quoted'") == "no markup: 2 * 3, 'quoted'"


def test_description_is_the_plain_first_line():
    assert description('"``atsvo-x``: one line.\n\nMore with ``markup``.') == '"atsvo-x: one line.'
    assert description("\n  ``atsvo-y``: first.\n") == "atsvo-y: first."
    assert description(None) == "" and description("") == ""


@pytest.mark.parametrize("module,prog,start", [
    (sim, "atsvo-sim", "atsvo-sim: generate a synthetic legged-robot sequence"),
    (demo, "atsvo-demo", "atsvo-demo: generate a synthetic legged-robot sequence (cached)"),
    (info, "atsvo-info", "atsvo-info: the environment"),
    (events, "atsvo-events", "atsvo-events: look inside event recordings."),
])
def test_help_has_no_rst_markup(capsys, module, prog, start):
    with pytest.raises(SystemExit) as exc:
        module.main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    assert out.startswith(f"usage: {prog}") and "``" not in out and ":func:" not in out
    assert start in " ".join(out.split())
