"""Command-line entry points: thin layers over the core, io, eval and sim packages."""
