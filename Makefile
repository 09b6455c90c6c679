# Lunaris: `make run` and `make test` do all the set-up on a fresh machine.
PYTHON ?= python3
VENV   ?= .venv
BIN     = $(VENV)/bin
ROVER  ?= config/rovers/mapp.yaml
STAMP   = $(VENV)/.installed

.PHONY: run test lint typecheck reference bench system-deps clean

# dev: the tools of make test; test-ros2: real ROS 2 (the rclpy wheels of the ros2 extra) and an
# independent rmw_zenoh client, which the bridge's tests run against.
$(STAMP): pyproject.toml
	@test -x $(BIN)/python || $(PYTHON) -m venv $(VENV)
	$(BIN)/python -m pip install --quiet --upgrade pip
	$(BIN)/python -m pip install --quiet -e '.[dev,test-ros2]'
	@touch $@

# docker-compose (v1, Debian) validates docker-compose.yml in the tests; no engine needed.
# chromium and chromium-driver (Debian) are the real browser the console's tests drive.
system-deps:
	@command -v docker-compose >/dev/null 2>&1 || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing docker-compose (Debian package) for the compose tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq docker-compose >/dev/null; \
	  else echo "warning: docker-compose missing and cannot be installed; compose tests will skip"; fi; }
	@{ command -v chromium >/dev/null 2>&1 && command -v chromedriver >/dev/null 2>&1; } || { \
	  if [ "$$(id -u)" = 0 ] && command -v apt-get >/dev/null 2>&1; then \
	    echo "installing chromium and chromium-driver (Debian packages) for the console's browser tests"; \
	    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium chromium-driver >/dev/null; \
	  else echo "warning: chromium or chromedriver missing and cannot be installed; console browser tests will skip"; fi; }

# The twin and the instructor console: open the address it prints (http://127.0.0.1:8080/).
run: $(STAMP)
	$(BIN)/lunaris up --rover $(ROVER) --console

lint: $(STAMP)
	$(BIN)/ruff check .

typecheck: $(STAMP)
	$(BIN)/mypy

# docs/reference is generated from the code; a test fails when the committed pages are stale.
reference: $(STAMP)
	$(BIN)/python -m lunaris.reference

# ruff, mypy, then every test with coverage (services' subprocesses included); the coverage
# table and total are printed at the end, and below 90 % the run fails.
test: $(STAMP) system-deps lint typecheck
	rm -f .coverage .coverage.*
	$(BIN)/pytest --cov --cov-report=term

bench: $(STAMP)
	$(BIN)/python bench/run_all.py

clean:
	rm -rf $(VENV) .pytest_cache .ruff_cache .hypothesis .mypy_cache .coverage .coverage.*
