# The two commands of the README, and their parts.
#   make run   - the Torobot in the simulated world (default config);
#                make run LOCKSTEP=1 runs it in lockstep (as fast as the CPU allows);
#                make run ROBOT=wall_follower runs a library robot of config/robots/
#                make run LUA=path/to/main.lua runs a program written for the original Torocó
#   make test  - every test suite: C port, detector, Common Test, PropEr, Dialyzer
.PHONY: run test deps compile port port-test lua-port lua-port-test detector detector-test ct dialyzer bench release board-check board-bench clean eval chaos

WORLD ?= config/worlds/default.world
SPEED ?= 1
N ?= 20
SEED ?= 1
WIRING ?= config/torobot.wiring

deps:
	@scripts/deps

compile: deps port lua-port
	rebar3 compile

port:
	@if [ -f c_src/pru_port/Makefile ]; then $(MAKE) -s -C c_src/pru_port; fi

port-test: deps
	@if [ -f c_src/pru_port/Makefile ]; then $(MAKE) -C c_src/pru_port test; fi

# The Lua behaviors' port program (SPEC §16, c_src/lua_port/README.md).
lua-port:
	@if [ -f c_src/lua_port/Makefile ]; then $(MAKE) -s -C c_src/lua_port; fi

lua-port-test: deps
	@if [ -f c_src/lua_port/Makefile ]; then $(MAKE) -C c_src/lua_port test; fi

detector: deps
	@if [ -f detector/CMakeLists.txt ]; then \
	  cmake -S detector -B _build/detector -DCMAKE_BUILD_TYPE=Release >/dev/null && \
	  cmake --build _build/detector -j2; fi

detector-test: detector
	@if [ -f detector/CMakeLists.txt ]; then ctest --test-dir _build/detector --output-on-failure; fi

ct: compile
	rebar3 ct

dialyzer: compile
	rebar3 dialyzer

test:
	scripts/test

run: compile
	SPEED=$(SPEED) SPLIT=$(SPLIT) LOCKSTEP=$(LOCKSTEP) TRACE=$(TRACE) REPLAY=$(REPLAY) LUA=$(LUA) scripts/run $(if $(ROBOT),config/worlds/$(ROBOT).world _build/$(ROBOT).svg config/robots/$(ROBOT).wiring,$(WORLD))

# The simulated lab: the wiring on N generated worlds, scored (SPEC §14).
# Lockstep by default; TIME=realtime [SPEED=10] for real time, and
# NODES=a@host,b@host spreads the runs over those nodes (README).
eval: compile
	TIME=$(TIME) NODES=$(NODES) scripts/eval $(N) $(SEED) $(WIRING) \
	  $(if $(filter command line environment,$(origin SPEED)),$(SPEED),10)

# The robustness lab: seeded fault schedules in lockstep, a property on
# each run, failures shrunk and replayable (SPEC §17, doc/lab.md):
#   make chaos [ROBOT=name] [WIRING=file] [N=1000] [FAULTS=file] [PROP=file] [RATES=0,0.1,0.5,1] [NODES=...]
chaos: compile
	ROBOT=$(ROBOT) WIRING_FILE=$(if $(filter command line,$(origin WIRING)),$(WIRING),) \
	  N=$(if $(filter command line environment,$(origin N)),$(N),1000) \
	  FAULTS=$(FAULTS) PROP=$(PROP) RATES=$(RATES) NODES=$(NODES) scripts/chaos

bench: compile
	scripts/bench

release: compile
	rebar3 as prod release

# The board release booted on Debian 12 armhf's Erlang under qemu (root; slow,
# not part of `make test'): doc/operations.md, "The board".
board-check: compile
	scripts/board-emulate

# CPU per event there, beside this machine's (doc/operations.md, "The emulated board"):
# the same step alone; BOARD_BENCH=1 make board-check runs both.
board-bench: compile
	BOARD_BENCH=only scripts/board-emulate

clean:
	rm -rf _build
	@if [ -f c_src/pru_port/Makefile ]; then $(MAKE) -C c_src/pru_port clean; fi
	@if [ -f c_src/lua_port/Makefile ]; then $(MAKE) -C c_src/lua_port clean; fi
