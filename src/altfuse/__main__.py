"""``python -m altfuse``: the same as the ``altfuse`` command."""

from altfuse.cli import main

main()
