"""The `ovon` command: thin parsers that call library functions and print."""
