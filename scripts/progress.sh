# Progress of a long shell job, sourced by scripts/setup_venv.sh (test/test_setup_progress.py runs it alone).
# On a terminal: ONE line, rewritten in place (carriage return, text, elapsed seconds, erase to the end of the
# line) at each step and every 2 s while a step runs; elsewhere (a log, CI): one line per step, no ticks.
# Set STEPS (the number of steps) before the first `step`; `ticking` starts the 2 s updates of the current
# step, `stop_ticking` ends them; `progress_done` ends both and the line on a terminal (also run at exit: what the
# shell prints next starts on a line of its own).
t0=$SECONDS
step_no=0
STEP=""
line_open=0
show() {
  if [ -t 1 ]; then printf '\r%s  %ds\033[K' "$STEP" $((SECONDS - t0)); line_open=1; else echo "$STEP"; fi
}
step() { step_no=$((step_no + 1)); STEP="setup [$step_no/$STEPS] $*"; show; }
tick_pid=""
ticking() { if [ -t 1 ]; then { while sleep 2; do show; done; } & tick_pid=$!; fi; }
stop_ticking() { if [ -n "$tick_pid" ]; then kill "$tick_pid" 2>/dev/null; wait "$tick_pid" 2>/dev/null; tick_pid=""; fi; }
progress_done() { stop_ticking; if [ "$line_open" = 1 ]; then echo; line_open=0; fi; }
trap progress_done EXIT
