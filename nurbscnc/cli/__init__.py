"""Command-line interface: parses options, calls one function per command, prints.

The command group is :data:`nurbscnc.cli.main.main` (the console script); each command is a
module of this package, registered on the group there.
"""
