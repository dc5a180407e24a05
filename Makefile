# Hindrax onboard stack. `make run` runs the main job, `make test` the tests; both set up .venv first.
SHELL := /bin/bash
VENV ?= .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.hindrax-setup-done
# Every process started from here keeps ROS 2 discovery on loopback (docs/architecture.md §11.4).
export ROS_AUTOMATIC_DISCOVERY_RANGE := LOCALHOST

SETUP_INPUTS := requirements.txt requirements-colcon.txt constraints.txt scripts/setup_venv.sh scripts/progress.sh \
	src/hindrax_msgs/CMakeLists.txt src/hindrax_msgs/package.xml \
	$(wildcard src/hindrax_msgs/msg/*.msg src/hindrax_msgs/srv/*.srv src/hindrax_msgs/action/*.action) \
	$(foreach p,common drivers bringup onboard fit sim tools,src/hindrax_$(p)/setup.py src/hindrax_$(p)/package.xml) \
	third_party/tf2_msgs/CMakeLists.txt third_party/tf2_msgs/package.xml $(wildcard third_party/tf2_msgs/msg/*.msg)

.PHONY: setup run test bench clean ros-install rig rig-pool-day

setup: $(STAMP)

# With RECORD_DURATIONS=1, setup's and a plain ros-install's times go into docs/results.md (section durations), which
# the README quotes; without it they change no tracked file (a fresh clone stays clean after make test).
RECORD_DURATIONS ?=
RESULTS_FOR_DURATIONS := $(if $(RECORD_DURATIONS),$(wildcard docs/results.md))
$(STAMP): $(SETUP_INPUTS)
	VENV=$(VENV) RESULTS_DOC=$(RESULTS_FOR_DURATIONS) bash scripts/setup_venv.sh
	touch $@

# Main job: a complete virtual pool identification campaign (options: make run RUN_ARGS="--dofs surge"); its table
# goes to docs/results.md (section run), as make bench's does (section bench).
run: setup
	$(VENV)/bin/hindrax run --results-doc docs/results.md $(RUN_ARGS)

# All tests (unit, emulator-to-driver, multi-process ROS, end to end). Extra pytest options: PYTEST_ARGS=...
test: setup
	$(PY) -m pytest $(PYTEST_ARGS)

bench: setup
	$(PY) -m hindrax_tools.bench --results-doc docs/results.md $(BENCH_ARGS)

# The vehicle on a Pi's CPU budget (hindrax_tools/benchmarks/rig.py; root, a cgroup cpu controller): the launch's processes in
# a cgroup of RIG_CORES cores here (a Pi 4 core = 0.2: 0.4 half a Pi, 0.8 the whole Pi), RIG_BUSY_LOOPS busy loops
# beside them, the virtual pool outside. rig: the stack bench's launch layout in it (rows rig_*); rig-pool-day: the
# README's pool day in it (test/test_pool_day.py, after make ros-install).
RIG_CORES ?= 0.4
RIG_BUSY_LOOPS ?= 0
rig: setup
	$(PY) -m hindrax_tools.benchmarks.stack --rig-cores $(RIG_CORES) \
	  --rig-busy-loops $(RIG_BUSY_LOOPS) --results-doc docs/results.md

rig-pool-day: setup
	HINDRAX_RIG_CORES=$(RIG_CORES) HINDRAX_RIG_BUSY_LOOPS=$(RIG_BUSY_LOOPS) \
	  $(PY) -m pytest -n0 -p no:randomly -s test/test_pool_day.py -k readme_writes

# The colcon workspace as the vehicle builds it: ros_ws/{build,install,log}, hindrax_msgs, hindrax_common,
# hindrax_drivers, hindrax_bringup and hindrax_onboard only (the fit, the simulator and the tools are topside: the
# venv's editable installs), against the venv's ROS wheels (the Pi builds the same packages against /opt/ros/jazzy; colcon comes with `make setup`). Then: source
# .venv/bin/activate && source ros_ws/install/setup.bash; `hindrax`, the nodes (ros_ws/install/lib/<package>/)
# and share/ are there. Extra colcon options: COLCON_ARGS="--symlink-install" (docs/deployment.md §3). A progress line
# shows what colcon builds (hindrax_tools.progress_run); RECORD_DURATIONS=1: a plain build's time into docs/results.md.
COLCON_ARGS ?=
ROS_INSTALL_RECORD := $(if $(and $(RESULTS_FOR_DURATIONS),$(if $(COLCON_ARGS),,plain)),--results-doc \
	$(abspath docs/results.md) --record "make ros-install")
ros-install: setup
	cd ros_ws && source $(abspath $(VENV))/bin/activate && \
	  AMENT_PREFIX_PATH=$$VIRTUAL_ENV CMAKE_PREFIX_PATH=$$VIRTUAL_ENV python -m hindrax_tools.progress_run ros-install \
	    $(ROS_INSTALL_RECORD) -- colcon build --merge-install --packages-up-to hindrax_onboard $(COLCON_ARGS) \
	    --event-handlers console_cohesion- --cmake-args -DPython3_EXECUTABLE=$$VIRTUAL_ENV/bin/python3 -DBUILD_TESTING=OFF

clean:
	rm -rf build $(VENV) .pytest_cache .hypothesis
