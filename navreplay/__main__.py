"""``python -m navreplay``: the same as the ``navreplay`` command."""

from navreplay.cli import main

main()
