"""Command-line interface: parses options, calls one function per command, prints.

The command group is :data:`nurbscnc.cli.main.main`; the commands of other modules are
registered on it here, so that importing the CLI (``nurbscnc.cli.main``, the console script)
always gives the whole group, and ``main`` never imports a module that imports it. (Module
imports only: binding ``main`` or ``stream`` here would hide the submodules of that name.)
"""

import nurbscnc.cli.identify as _identify
import nurbscnc.cli.main as _main
import nurbscnc.cli.profile as _profile
import nurbscnc.cli.stream as _stream

_main.main.add_command(_stream.stream)
_main.main.add_command(_stream.card_sim)
_main.main.add_command(_stream.card_position)
_main.main.add_command(_profile.profile)
_main.main.add_command(_identify.identify)
