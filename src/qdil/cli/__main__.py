"""``python -m qdil.cli``: the ``qdil`` command."""

from qdil.cli import main

main()
