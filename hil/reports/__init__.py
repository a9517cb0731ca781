"""Reports: HTML per plan and per run, JUnit XML."""
