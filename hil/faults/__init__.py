"""Faults: the catalogue (what can be injected and its arguments) and the injector that
switches them on and off in a running session, from a plan, Modbus or Python."""
from hil.faults.injector import (FaultInjector, apply_fault, apply_fault_bits, injector)

__all__ = ["FaultInjector", "apply_fault", "apply_fault_bits", "injector"]
