# ctxsearch: two-command quick start.  `make demo` runs the main job, `make test` the tests.
# Both create .venv on demand from requirements.lock (pinned) and are no-ops when nothing changed.
SHELL := /bin/bash
PYTHON ?= python3
VENV := .venv
PY := $(VENV)/bin/python
STAMP := $(VENV)/.ctxsearch-installed
export MUJOCO_GL ?= egl
export PYOPENGL_PLATFORM ?= egl

.PHONY: demo test bench bench-timing bench-a bench-b bench-home-full bench-unknown-home bench-full kb-home lint syscheck clean help

help:
	@echo "make demo   - learn in a few office rooms, then search with and without context (writes demo/)"
	@echo "make test   - run the test suite"
	@echo "make bench  - run the benchmarks (writes results/)"
	@echo "make bench-full - the benchmark at full power, resumable (writes results/full/)"
	@echo "make lint   - ruff"

$(STAMP): pyproject.toml requirements.lock
	@$(PYTHON) scripts/syscheck.py
	@test -x $(PY) || $(PYTHON) -m venv $(VENV)
	$(PY) -m pip install -q --disable-pip-version-check -r requirements.lock
	$(PY) -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
	@touch $(STAMP)

syscheck:
	@$(PYTHON) scripts/syscheck.py

demo: $(STAMP)
	$(VENV)/bin/ctxsearch demo

# The suite on every CPU (pytest-xdist; a test file's tests stay on one worker, so its module
# fixtures are built once). TEST_WORKERS=0 runs it in this process.
TEST_WORKERS ?= $(shell nproc 2>/dev/null || echo 1)
test: $(STAMP)
	$(PY) -m pytest -n $(TEST_WORKERS) --dist loadfile

# Regenerates every result the README quotes: the wall-clock timings alone, then two lanes side
# by side (make -j2, their lines interleaved): lane A starts with the steps that
# run on one core (the hierarchy, the oracle learning runs), lane B with the curve (whose
# learning run is one core's too), so no core idles while a one-core step runs; lane A also
# takes the apartment's intervals and the rooms, so that it runs beside lane B for longer and
# fills the one-core moments of B's steps (their truths, tails and tables). The steps write
# disjoint files and every result is deterministic, so the lanes' order does not change a number.
# Time on 2 cores: 48 minutes on 2026-12-04, 61 and 63 before the last changes (docs/usage.md).
# The sweeps (truth, bench learning, bench search, curve, transfer, intervals, drift) run their
# units on WORKERS local CPUs (Ray; 1: serially, no Ray); the results are the same for any WORKERS.
WORKERS ?= $(shell nproc 2>/dev/null || echo 1)
STRATEGIES := hif,random,round-robin,nearest,fewest,expected-hif,cost-hif
CTX := $(VENV)/bin/ctxsearch
T := sh scripts/timed.sh  # each step prints its wall-clock time
bench: $(STAMP)
	@start=$$(date +%s); \
	$(MAKE) --no-print-directory bench-timing && \
	$(MAKE) --no-print-directory -j2 --output-sync=line bench-a bench-b && \
	echo "make bench: $$(( ($$(date +%s) - start) / 60 )) min"

# Wall-clock timings first, alone on the machine.
bench-timing: $(STAMP)
	$(T) $(CTX) bench kb --out results
	$(T) $(CTX) bench sim --out results
	$(T) $(CTX) bench sim --style apartment --rooms 3 --gazes 50 --explore 3 --out results/sim_apartment

bench-a: $(STAMP)
	$(T) $(CTX) bench hierarchy --style office --quiet --out results/hierarchy
	$(T) $(CTX) bench learning --style office --rooms 10 --seeds 3 --strategies hif --interval clustered --truth-samples 100 --out results/intervals/oracle
	rm -f build/kb_office.sqlite && mkdir -p build
	$(T) $(CTX) learn --style office --rooms 30 --perception oracle --kb build/kb_office.sqlite --no-progress
# Search (issue 12): paired episodes, the target not visible from the start, feasible, the
# realistic detector. The small-world reference: 40 office episodes on the given map.
	$(T) $(CTX) bench search --kb build/kb_office.sqlite --style office --episodes 40 --quiet --out results/search --workers $(WORKERS)
# A drifting world set: forgetting methods (about a minute on 2 cores, oracle perception).
	$(T) $(CTX) bench drift --out results/drift --workers $(WORKERS)
	for s in office biology_lab living_room kitchen; do \
	  $(T) $(CTX) truth --style $$s --samples 200 --out results/truth/$$s.json --no-progress --workers $(WORKERS); done
# Detector x interval against the truth, camera mode, apartment after 3 and 10 houses (14 runs: 7
# detector settings x 2 seeds).
	$(T) $(CTX) bench intervals --styles apartment --rooms 3,10 --seeds 2 --truth-samples 400 --out results/intervals_apartment --workers $(WORKERS)
# Detector x interval against the truth, camera mode: office after 10 and 30 rooms (14 runs: 7
# detector settings x 2 seeds). Measured on 2026-12-06 (52 minutes in all, a clean clone): lane A
# 49 minutes, lane B 50 (the remembered map's find-my-phone pair lives in make bench-unknown-home).
	$(T) $(CTX) bench intervals --styles office --rooms 10,30 --seeds 2 --truth-samples 400 --out results/intervals --workers $(WORKERS)
# The robot's rooms against the plans: 10 houses of every stock house style, explored and segmented.
	$(T) $(CTX) bench rooms --houses 10 --out results/rooms --workers $(WORKERS)
	$(T) $(CTX) room --style family_house --seed 1 --views 0 --out results/rooms/family_house_1
# The changing home: the robot lives 4 days in 12 apartments (two learning runs, one core each,
# merged), then is asked for small types 1 and 4 days after its last map, half the queries for
# types that stayed where it saw them (every arm: uniform, memory, location, both, the bound).
	$(MAKE) --no-print-directory kb-home
	$(T) $(CTX) bench home --kb build/kb_home.sqlite --style apartment --episodes 40 --days-after 1,4 --room-context --quiet --out results/home --workers $(WORKERS) --draw-cache build/draws

# The store the changing home's benchmarks search in: learned anew by make bench (kb-home), once
# by make bench-home-full if it is missing.
build/kb_home.sqlite:
	$(MAKE) --no-print-directory kb-home

kb-home: $(STAMP)
	rm -f build/kb_home.sqlite build/kb_home0.sqlite build/kb_home1.sqlite build/kb_home*.sqlite-*
	mkdir -p build
	$(T) $(CTX) learn --style apartment --rooms 6 --days 4 --detector realistic --seed 0 --kb build/kb_home0.sqlite --no-progress
	$(T) $(CTX) learn --style apartment --rooms 6 --days 4 --detector realistic --seed 1 --kb build/kb_home1.sqlite --no-progress
	$(CTX) kb merge build/kb_home.sqlite build/kb_home0.sqlite build/kb_home1.sqlite

# The changing home at 400 paired queries a day after the robot's last map (about 30 minutes on
# 2 cores; results/home_400).
bench-home-full: build/kb_home.sqlite
	$(T) $(CTX) bench home --kb build/kb_home.sqlite --style apartment --episodes 400 --days-after 1 --room-context --quiet --out results/home_400 --workers $(WORKERS) --draw-cache build/draws

# The unknown home beyond make bench (about three hours on 2 cores, after make bench: it searches
# make bench's store and reads its draws; an estimate: 130 minutes measured before the 400-episode
# runs, which took about 105 CPU minutes, and the family houses' places beyond 34): room context
# on the built map with and without the next-room relations (200 paired apartment episodes each;
# results/search_apartment_built_rooms, _next), the next-room relations and places beyond the
# frontier on 400 paired apartment episodes (without places beyond, with the furniture plan's
# bound: results/search_apartment_built_next_400; with them: results/search_apartment_built_beyond,
# its bounds results/search_apartment_built_beyond_bounds, and glimpsed furniture's room taken to
# reach 4 m: results/search_apartment_built_beyond_glimpse4), the family houses' ladder of bounds
# with the given map's policies on the same episodes, the next-room relations there and places
# beyond the frontier (results/search_family_house_*), "find my phone" with room
# context on three maps, the same 60 held-out houses on the day after the robot toured each:
# remembered, given and built (results/search_apartment_{remembered,given,built}_instance); the
# control style without layout rules
# (apartment_shuffled: 30 houses learned, then room context with and without the next-room
# relations on 200 paired episodes, and with places beyond the frontier;
# results/search_apartment_shuffled_built_{rooms,next,beyond}).
bench-unknown-home: $(STAMP)
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --quiet --out results/search_apartment_built_rooms --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --set knowledge.next_rooms=true --quiet --out results/search_apartment_built_next --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies frontier,indirect,oracle-prior-indirect,bound-plan --episodes 400 --room-context --set knowledge.next_rooms=true --quiet --out results/search_apartment_built_next_400 --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies frontier,indirect,oracle-prior-indirect --episodes 400 --room-context --set knowledge.next_rooms=true --set online.beyond=true --quiet --out results/search_apartment_built_beyond --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies frontier,bound-rooms,bound-plan --episodes 400 --room-context --set knowledge.next_rooms=true --set online.beyond=true --quiet --out results/search_apartment_built_beyond_bounds --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --policies indirect,oracle-prior-indirect --episodes 400 --room-context --set knowledge.next_rooms=true --set online.beyond=true --set knowledge.glimpse_m=4 --quiet --out results/search_apartment_built_beyond_glimpse4 --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map remembered --set map.home=tour --policies uniform,location,oracle-prior,oracle --episodes 60 --targets instance --room-context --quiet --out results/search_apartment_remembered_instance --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map given --set map.days_after=1 --policies uniform,location,oracle-prior,oracle --episodes 60 --targets instance --room-context --quiet --out results/search_apartment_given_instance --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --set map.days_after=1 --policies frontier,indirect,oracle-prior-indirect,oracle --episodes 60 --targets instance --room-context --quiet --out results/search_apartment_built_instance --workers $(WORKERS) --draw-cache build/draws
	rm -f build/kb_family_house.sqlite build/kb_family_house.sqlite-wal build/kb_family_house.sqlite-shm
	$(T) $(CTX) learn --style family_house --rooms 30 --kb build/kb_family_house.sqlite --no-progress
	$(T) $(CTX) bench search --kb build/kb_family_house.sqlite --style family_house --map built --episodes 200 --quiet --out results/search_family_house_built --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_family_house.sqlite --style family_house --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --set knowledge.next_rooms=true --quiet --out results/search_family_house_built_next --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_family_house.sqlite --style family_house --map given --policies uniform,location,oracle-prior,oracle --episodes 200 --quiet --out results/search_family_house_given --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_family_house.sqlite --style family_house --map built --policies frontier,indirect,oracle-prior-indirect,bound-rooms --episodes 200 --room-context --set knowledge.next_rooms=true --set online.beyond=true --quiet --out results/search_family_house_built_beyond --workers $(WORKERS) --draw-cache build/draws
	rm -f build/kb_apartment_shuffled.sqlite build/kb_apartment_shuffled.sqlite-wal build/kb_apartment_shuffled.sqlite-shm
	$(T) $(CTX) learn --style apartment_shuffled --rooms 30 --kb build/kb_apartment_shuffled.sqlite --no-progress
	$(T) $(CTX) bench search --kb build/kb_apartment_shuffled.sqlite --style apartment_shuffled --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --quiet --out results/search_apartment_shuffled_built_rooms --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment_shuffled.sqlite --style apartment_shuffled --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --set knowledge.next_rooms=true --quiet --out results/search_apartment_shuffled_built_next --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment_shuffled.sqlite --style apartment_shuffled --map built --policies frontier,indirect,oracle-prior-indirect --episodes 200 --room-context --set knowledge.next_rooms=true --set online.beyond=true --quiet --out results/search_apartment_shuffled_built_beyond --workers $(WORKERS) --draw-cache build/draws

# The benchmark at full power (scripts/experiments/bench_full.py; results/full/, its journal, step
# stamps, draws and family-house store in build/full/): the apartment learning curve (100 paired
# episodes per k), apartments (APARTMENT_EPISODES paired episodes per map scenario) and family
# houses (FAMILY_EPISODES), instance targets ("find my phone") and type targets, room context on
# for the context policies and, on instance targets, those policies without it; the transfer
# table (100 per cell); summary.md. Every step resumes: kill it at any moment (even SIGKILL) and
# run make bench-full again; finished steps are skipped, finished units read back (--journal),
# and the files are those of an uninterrupted run. A line per step says the time spent and left.
# Estimated time on 2 cores: about 3.8 hours (+-30%; from CPU seconds per episode measured on
# 2026-12-05, docs/usage.md "make bench-full"); the counts the benchmark was first asked for
# (family houses 200, type targets as many as instance targets) would take about 5.2, so the
# defaults are apartments 400 (instance) / 150 (type), family houses 120 / 60, the curve 100 per
# k, the transfer 100 per cell. RAY_ADDRESS=HOST:PORT runs the sweeps on a Ray cluster.
bench-full: $(STAMP)
	$(PY) -m ctxsearch.scripts.experiments.bench_full --workers $(WORKERS) $(if $(RAY_ADDRESS),--ray-address $(RAY_ADDRESS))

bench-b: $(STAMP)
# Does learning pay? The paired search ratio after k learned houses, built and given map (issue
# 12), and context learned in one room style used in another.
	rm -rf results/curve/stores results/transfer/stores
	$(T) $(CTX) bench curve --style apartment --rooms 0,1,3,10,30 --seed 0 --episodes 20 --quiet --out results/curve --workers $(WORKERS)
# The headline: houses after 30 learned houses, 200 paired episodes per map scenario. The store is
# the curve's after 30 houses: the same run as `ctxsearch learn --style apartment --rooms 30 --kb
# build/kb_apartment.sqlite` (same intervals, 2079 examinations), not learned twice; the old
# store's WAL files go too (SQLite would replay a stale log into the copy). Both scenarios search
# the same 200 episodes: the second reads the first's draw from build/draws (--draw-cache); the
# built map's default policies include the ladder of bounds (bound-rooms, bound-target-room,
# bound-plan: what exact knowledge of one kind would buy there; docs/results.md). The office's
# learning runs (HIF against other strategies) end this lane, which balances the two.
	rm -f build/kb_apartment.sqlite build/kb_apartment.sqlite-wal build/kb_apartment.sqlite-shm
	mkdir -p build && cp results/curve/stores/k=0030.sqlite build/kb_apartment.sqlite
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map built --episodes 200 --quiet --out results/search_apartment_built --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench search --kb build/kb_apartment.sqlite --style apartment --map given --episodes 200 --quiet --out results/search_apartment_given --workers $(WORKERS) --draw-cache build/draws
	$(T) $(CTX) bench transfer --styles office,biology_lab --rooms 10 --episodes 30 --quiet --out results/transfer --workers $(WORKERS)
	$(T) $(CTX) bench learning --style office --rooms 20 --seeds 5 --strategies $(STRATEGIES) --out results/learning --workers $(WORKERS)
	$(T) $(CTX) bench learning --style office --rooms 20 --seeds 5 --strategies $(STRATEGIES) --room-budget 60 --out results/learning_budget --workers $(WORKERS)

lint: $(STAMP)
	$(VENV)/bin/ruff check .
	$(VENV)/bin/ruff format --check .

clean:
	rm -rf $(VENV) build *.egg-info .pytest_cache .ruff_cache
