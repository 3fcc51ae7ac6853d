"""Front doors besides EtherCAT (TMCL, LIN, the PDI SPI socket, EoE TAP devices): the host
that serves them in one event loop and their construction from a segment file."""
