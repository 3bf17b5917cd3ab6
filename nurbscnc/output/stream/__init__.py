"""Streaming reference points to a pulse-train motion card (issue 6).

- :mod:`.quantise`: reference points [mm] → signed pulse counts per servo period and axis.
- :mod:`.protocol`: the framed, CRC-checked binary protocol; one codec shared by the sender
  and the card simulator (described in ``docs/protocol.md``).
- :mod:`.sender`: the reliable sender (sequence numbers, ack/nak, retransmission, credit-based
  flow control, abort).
- :mod:`.card`: the card simulator (``nurbscnc card-sim``) with fault injection.
- :mod:`.commands`: the ``stream`` and ``card-sim`` click commands.
"""
