"""The control socket: its server in the daemon, the table ``ecatsim ctl status`` prints and
a client for test suites (``ecatsim.ctl.client``)."""
