"""The TMC8460's SPI slave interfaces as sockets: external slave firmware drives the chip.

``protocol``: the SPI datagram of TMC8460 §3.5.1, one chip-select frame at a time.
``door``: the unix stream socket carrying those frames, and the PDI IRQ line beside it.
``external``: a slave whose firmware is outside ecatsim (``firmware: external``).
"""
