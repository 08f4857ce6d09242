"""``python -m modelgen``: the same command line as ``modelgen``."""

from modelgen.cli import main

if __name__ == "__main__":
    main(prog_name="modelgen")
