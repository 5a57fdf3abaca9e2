"""`python -m syncaudit.cli`: the command line."""

from syncaudit.cli import main

main()
