"""Logs: the MCAP writer every run leaves, the per-period recorder that feeds it, the reader
that recovers even a killed run's file, and the `hil log` commands."""
