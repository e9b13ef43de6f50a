"""``python -m qdil.cli``: the ``qdil`` command."""

from qdil.cli import main

if __name__ == "__main__":  # importing the module (e.g. to check imports) runs nothing
    main()
