"""`python -m velogauss.walkthrough --out DIR`: write DIR/walkthrough.md and DIR/figures/."""

import argparse

from velogauss.walkthrough.build import write_walkthrough


def main(argv=None):
    parser = argparse.ArgumentParser(
        prog="python -m velogauss.walkthrough",
        description="Write the equation-by-equation walkthrough (walkthrough.md and figures/) "
                    "by running the NumPy reference. The committed copy lives in docs/.")
    parser.add_argument("--out", required=True, help="output folder (docs to refresh the committed copy)")
    args = parser.parse_args(argv)
    try:
        path = write_walkthrough(args.out)
    except ValueError as err:
        parser.error(str(err))
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
