"""``python -m spikectl.cli``: the ``spikectl`` command, as the tests run it.

The installed ``spikectl`` script enters through ``_spikectl_launcher`` instead, which
also turns a Ctrl-C or a bad ``NUMBA_*`` variable while the package loads into one line;
here the package has loaded before this module runs.
"""

from spikectl.cli import main

if __name__ == "__main__":
    main()
