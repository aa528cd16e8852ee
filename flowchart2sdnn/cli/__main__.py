"""`python -m flowchart2sdnn.cli ...` is `sdnn ...`."""

from . import main

main()
