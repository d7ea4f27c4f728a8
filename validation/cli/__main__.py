"""``python -m validation.cli``: the ``geodesics`` command without the console script."""

from validation.cli.entry import main

main()
