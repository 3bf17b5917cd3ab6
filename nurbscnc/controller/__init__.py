"""The controller: running a planned job on the card, between ``plan/`` and ``output/``.

- :mod:`.job`: :class:`~.job.Job` cuts the program into sections at its stops and applies the
  operator's feed hold and feed override (free of I/O and clocks).
- :mod:`.motion`: playing a plan at a feed override, stopping it, re-planning the rest.
- :mod:`.override`: feed override changes (a ramp below 100 %, a re-plan above).
- :mod:`.feed`: the plan's cut windows handed to the job as they are planned.
- :mod:`.stops`: the program's stops (M0, M1, M60, M6, M100–M199) and run-from-line.
- :mod:`.run`: the section loop: it drives a card object (``output``'s sender) and the
  operator's callables handed in by the command; it does no I/O itself.
- :mod:`.simulate`: a job on a simulated card in virtual time, through that loop.

It ranks above ``output`` (tests/test_layers.py): a job's sections are quantised with
``output.stream.quantise`` and its changes applied to ``output.stream.link``'s running link.
"""
