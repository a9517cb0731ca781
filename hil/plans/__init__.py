"""Plans: the YAML plan format (steps, stimuli, marks), checks and their kinds, limits,
outcomes at three levels, the signal catalogue and units. Plans are data, never code."""
