# The two Quick start commands: `make run` (the paper's acceptance plans against the
# stub in virtual loopback) and `make test` (every test). Both set themselves up: `make run`
# with only what running plans needs (python3 with venv and headers, gcc, make; the QEMU plan
# reports SKIPPED without QEMU and the Arm toolchain), `make test` with the whole test toolchain.
.PHONY: run test bootstrap bootstrap-run clean

OUT ?= out

bootstrap:
	@bash scripts/bootstrap.sh --test

bootstrap-run:
	@bash scripts/bootstrap.sh --run

run: bootstrap-run
	.venv/bin/hil run test_plans/ --out $(OUT)
	.venv/bin/hil run examples/hall_sixstep/plans --link lib:examples/hall_sixstep/build/libhall_sixstep.so --out $(OUT)/hall_sixstep
	.venv/bin/hil run examples/bemf_sixstep/plans --link lib:examples/bemf_sixstep/build/libbemf_sixstep.so --out $(OUT)/bemf_sixstep

test: bootstrap
	$(MAKE) -s -C protocol/c test
	$(MAKE) -s -C firmware_stub test
	$(MAKE) -s -C examples/sixstep test
	$(MAKE) -s -C examples/hall_sixstep test
	$(MAKE) -s -C examples/bemf_sixstep test
	$(MAKE) -s -C examples/spec_minimal test
	$(MAKE) -s -C protocol/c ext-san
	$(MAKE) -s -C plant_rt/c ext-san
	.venv/bin/python -m pytest -q

clean:
	$(MAKE) -s -C protocol/c clean
	$(MAKE) -s -C plant_rt/c clean
	$(MAKE) -s -C firmware_stub clean
	rm -rf $(OUT)
