"""The TMC8460 MFCIO block: encoder, SPI master, step/direction, PWM, GPIO, IRQ and IO
watchdog, reachable through the PDRAM memory blocks MB0/MB1. Ref: TMC8460 §6."""
