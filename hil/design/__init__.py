"""Design tools: derivations of the stub's gains from the motor and noise data."""
