"""Plant emulator: the paper's PM brushless AC motor, its inverter, DC link, load and sensors,
advanced one control period at a time (see docs/plant.md)."""
from plant_rt.plant import TRUTH_FIELDS, Plant
from plant_rt.profile import BenchProfile, default_profile_path, load_profile
from plant_rt.sensor_set import SensorFrame
from plant_rt.sensors import SensorSample

__all__ = ["Plant", "BenchProfile", "load_profile", "default_profile_path", "SensorSample",
           "SensorFrame", "TRUTH_FIELDS"]
