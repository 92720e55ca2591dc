"""`python -m conag ...` is the same as the `conag` console script."""

from conag.cli import main

raise SystemExit(main())
