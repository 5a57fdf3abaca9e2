"""`python -m syncaudit`: the command line."""

from syncaudit.cli import main

main()
