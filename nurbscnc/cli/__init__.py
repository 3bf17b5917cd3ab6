"""Command-line interface: parses options, calls one function per command, prints."""
