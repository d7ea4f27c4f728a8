"""``python -m validation.cli``: the ``geodesics`` command without the console script."""

from validation.cli.entry import main

if __name__ == "__main__":  # importing the module (a package scan) must not run the CLI
    main()
