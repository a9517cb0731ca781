"""Ports: the bench as a server for lab tools (Modbus TCP/RTU control port)."""
