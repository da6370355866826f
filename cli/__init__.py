"""Command line: click commands that parse options, call the library, print."""
