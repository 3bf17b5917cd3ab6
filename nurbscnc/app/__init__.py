"""The application layer: what a command does, without a terminal.

Between the pipeline (:mod:`nurbscnc.pipeline`) and the command line (:mod:`nurbscnc.cli`):
reading program files, tool tables and machine profiles, planning a program from option
values, shaping summaries and reports as JSON-ready data, writing point files, profiles and
figures, preparing a stream. Functions here return data or raise
:class:`~nurbscnc.errors.NurbsCncError`; they print nothing. Only the CLI turns exceptions
into messages and exit codes.

Start-up: the modules import only the standard library at the top (the CLI imports some of
them for every command, ``--help`` included); numpy, the interpreter and the planner are
imported by the functions that use them.
"""
