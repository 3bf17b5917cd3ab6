"""Streaming reference points to a pulse-train motion card (version 2 of the protocol).

- :mod:`.quantise`: reference points [mm] → signed pulse counts per servo period and axis.
- :mod:`.protocol`: the framed protocol (header CRC-8, CRC-32, batches that carry their start
  position); one codec shared by the sender and the card simulator (``docs/protocol.md``).
- :mod:`.link`: the sender's protocol logic, free of I/O and clocks (selective repeat,
  retransmission, credit flow control, hold/resume, abort, the card's final state decides).
- :mod:`.sender`: :class:`~.sender.Sender` drives the link on a serial port; ``open_port``.
- :mod:`.card`: the card simulator (``nurbscnc card-sim``) with fault injection.
- :mod:`.simlink`: sender and card over a simulated faulty line in virtual time (tests, bench).

The ``stream`` and ``card-sim`` commands are in :mod:`nurbscnc.cli.stream`.
"""
