"""`python -m velogauss.walkthrough --out DIR`: an alias of `velogauss walkthrough --out DIR`."""

import sys

from velogauss.cli import main

main(["walkthrough", *sys.argv[1:]], prog_name="velogauss")
