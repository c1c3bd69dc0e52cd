"""Benchmarks (``atsvo-bench``): speed, accuracy, memory and node latency, side by side with the peers.

One module per benchmark; :mod:`.cli` registers them as subcommands and :mod:`.suite` runs them all.
Benchmarks, never timed tests.
"""
