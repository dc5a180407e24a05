"""The process and its system: lifecycle, CPU scheduling, systemd, DDS transport, sockets, waits."""
