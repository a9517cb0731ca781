# The two Quick start commands: `make run` (the paper's acceptance plans against the
# stub in virtual loopback) and `make test` (every test). Both set themselves up.
.PHONY: run test bootstrap clean

OUT ?= out

bootstrap:
	@bash scripts/bootstrap.sh

run: bootstrap
	.venv/bin/hil run test_plans/ --out $(OUT)

test: bootstrap
	$(MAKE) -s -C protocol/c test
	$(MAKE) -s -C firmware_stub test
	$(MAKE) -s -C examples/sixstep test
	$(MAKE) -s -C examples/spec_minimal test
	$(MAKE) -s -C protocol/c ext-san
	$(MAKE) -s -C plant_rt/c ext-san
	.venv/bin/python -m pytest -q

clean:
	$(MAKE) -s -C protocol/c clean
	$(MAKE) -s -C plant_rt/c clean
	$(MAKE) -s -C firmware_stub clean
	rm -rf $(OUT)
