"""`python -m velogauss ...`: the `velogauss` command, for a Python without its console script."""

from velogauss.cli import main

main()
