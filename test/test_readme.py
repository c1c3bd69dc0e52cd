"""The README names only what exists: console scripts, config keys, topics, files and docs pages."""
from __future__ import annotations

import re
from pathlib import Path

from atsvo_ros.config import flatten, load_config

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()
SOURCES = "\n".join(p.read_text() for p in (ROOT / "atsvo_ros").rglob("*.py")) + "\n".join(
    p.read_text() for p in (ROOT / "config").glob("*.yaml"))


def test_readme_is_short():
    assert len(README.splitlines()) <= 300


def test_every_console_script_named_exists():
    setup = (ROOT / "setup.py").read_text()
    scripts = set(re.findall(r'"([\w-]+) = atsvo_ros\.', setup))
    named = set(re.findall(r"\b(atsvo-[a-z]+|atsvo_node|tracking_node|mapping_node)\b", README))
    assert named and named <= scripts, named - scripts


def test_every_config_key_named_exists():
    keys = set(flatten(load_config("mini_cheetah")))
    sections = {k.split(".")[0] for k in keys}
    named = {m for m in re.findall(r"`([a-z_]+\.[a-z_0-9]+)`", README) if m.split(".")[0] in sections}
    alternatives = "|".join(sections)
    named |= {m for m in re.findall(rf"\b((?:{alternatives})\.[a-z_0-9]+)", README)
              if not m.endswith((".py", ".md", ".yaml"))}
    missing = {k for k in named if k not in keys and not any(x.startswith(k + ".") for x in keys)
               and not k.endswith(".*")}
    assert named and not missing, missing


def test_every_topic_named_exists():
    named = set(re.findall(r"`(/[a-z_]+(?:/[a-z_0-9]+)*)`", README)) | set(
        re.findall(r"(?<![\w.])(/(?:camera|dvxplorer|atsvo)(?:/[a-z_0-9]+)+)", README))
    named = {t for t in named if not t.startswith(("/path", "/tmp"))}
    missing = {t for t in named if f'"{t}"' not in SOURCES and f"{t}\n" not in SOURCES and f" {t}" not in SOURCES}
    assert named and not missing, missing


def test_every_file_and_page_named_exists():
    named = set(re.findall(r"\]\(((?:docs|config)/[\w./-]+)\)", README)) | set(
        re.findall(r"`((?:config|docs|launch|test)/[\w./-]+\.(?:yaml|md|py|xml))`", README))
    missing = {p for p in named if not (ROOT / p).exists()}
    assert named and not missing, missing
