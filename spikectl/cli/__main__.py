"""``python -m spikectl.cli``: the ``spikectl`` command."""

from spikectl.cli import main

if __name__ == "__main__":
    main()
