# hindrax_msgs' compiles through ccache: the settings scripts/setup_venv.sh builds with, and
# the suite's `make ros-install` builds with again (test/conftest.py runs this file and takes
# what it exports). One file, so the two cannot drift apart: with any difference the suite's
# 175 compiles miss setup's cache (twice the time).
# Sourced with the repository root as the working directory.
# - CCACHE_BASEDIR: paths under build/ are hashed as relative ones (the suite builds in a copy
#   under build/colcon-test/).
# - CCACHE_DEPEND: no extra preprocessor run.
# - PYTHONHASHSEED: rosidl's generators write their #includes in one order, so both builds'
#   generated sources are byte-identical.
export CCACHE_DIR="$PWD/build/ccache" CCACHE_BASEDIR="$PWD/build" CCACHE_DEPEND=1 PYTHONHASHSEED=0
