"""Running plans: the runner (a plan on a session, results, reports) and the pytest plugin
that runs plans as test items and offers the `bench` fixture."""
