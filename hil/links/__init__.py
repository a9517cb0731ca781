"""Links: one string names the board the bench talks to (stub, stub-pty, stub-can, qemu,
serial:PORT, can:INTERFACE:CHANNEL); `connect(spec)` opens it as a BoardConnection."""
