"""The EtherCAT bus: the daemon and its loop, the per-frame sequence, the segment and its
topology, the compiled responder, the segment's assembly from its files and ``ecatsim run``."""
