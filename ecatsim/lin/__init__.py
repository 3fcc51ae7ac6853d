"""TMC211 stepper nodes on an emulated LIN bus (a pseudo-terminal).

The bus as a LIN master's UART sees it: break (as the byte 0x00), sync 0x55, protected
identifier, data and classic checksum (TMC211 datasheet §6, LIN specification rev. 1.3).
Each node runs the TMC211 position controller, ramp generator and command-priority state
machine on the injected simulated clock (TMC211 §5.1).
"""
