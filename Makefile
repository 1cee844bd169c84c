# Relightable Textures -- two commands on a fresh machine: `make demo` and `make test`.
PYTHON ?= python3
VENV   := .venv
PY     := $(VENV)/bin/python
STAMP  := $(VENV)/.installed
OUT    := out
# Never touch the user's real Blender configuration from make targets.
export BLENDER_USER_RESOURCES ?= $(CURDIR)/build/blender-user

.PHONY: venv demo test test-core bench bench-full fuzz dist matrix validate clean

venv: $(STAMP)

# The venv's wheels come from a wheelhouse kept under ~/.cache (pip's own cache does not persist
# on every machine: a fresh clone re-downloaded ~430 MB): the registry is asked only when the
# wheelhouse lacks a pinned wheel, so a warm machine builds the venv offline.
WHEELHOUSE  ?= $(HOME)/.cache/relightable-textures/wheelhouse
PIP_OFFLINE := $(PY) -m pip install --quiet --no-index --find-links $(WHEELHOUSE)
VENV_PKGS   := --upgrade pip setuptools -r requirements.txt

$(STAMP): requirements.txt pyproject.toml
	$(PYTHON) -m venv $(VENV)
	$(PIP_OFFLINE) $(VENV_PKGS) 2>/dev/null || { \
	  $(PY) -m pip download --quiet -d $(WHEELHOUSE) pip setuptools -r requirements.txt && \
	  $(PIP_OFFLINE) $(VENV_PKGS); }
	# an egg-info left in the checkout by an older setuptools shadows the venv's entry points
	# (the plugins of lt_addon/plugins.py) wherever the checkout is on sys.path
	rm -rf relightable_textures.egg-info
	$(PIP_OFFLINE) --no-deps --no-build-isolation -e .
	touch $(STAMP)

## demo: set up the venv and run the main job on the bundled sample scenes (writes out/; its
##   time on 2 cores with the venv in place: README.md's make demo line)
demo: $(STAMP)
	mkdir -p $(OUT) $(BLENDER_USER_RESOURCES)
	for s in bumps noise statue room; do \
	  $(VENV)/bin/relight scene $$s --size demo --out $(OUT)/$$s.blend --force || exit 1; \
	done
	$(VENV)/bin/relight validate --paper ashikhmin2002 > $(OUT)/validate-ashikhmin2002.json
	$(VENV)/bin/relight bake-textures $(OUT)/bumps.blend --object Bumps --preset balanced \
	  --truth 4 --force
	$(VENV)/bin/relight compare $(OUT)/bumps.blend --light 37,10 --sun-angle 2 --resolution 384 \
	  --out $(OUT)/bumps-compare-low-sun.png --force
	$(VENV)/bin/relight bake-textures $(OUT)/statue.blend --object Statue --object Ground \
	  --preset draft --truth 4 --force
	$(VENV)/bin/relight compare $(OUT)/statue.blend --light 200,15 --sun-angle 2 \
	  --out $(OUT)/statue-compare-low-sun.png --force
	$(VENV)/bin/relight bake-transport $(OUT)/statue.blend --object Statue --directions cube:8 \
	  --energy 0.99 --truth --force
	$(VENV)/bin/relight bake-materials $(OUT)/room.blend --object Floor --object WallLeft \
	  --object WallRight --object WallBack --object Box --region RedMaterial \
	  --region GreenMaterial --per-corner --force
	$(VENV)/bin/relight relight-materials $(OUT)/room.blend --object Floor \
	  --set RedMaterial.color=0.1,0.2,0.8 --compare $(OUT)/room-edit-vs-cycles.png \
	  --out $(OUT)/room_edit_shading.npy --force
	$(VENV)/bin/relight info $(OUT)/bumps.blend
	$(VENV)/bin/relight info $(OUT)/statue.blend
	@echo "demo: open $(OUT)/bumps.blend or $(OUT)/statue.blend in Blender (Relight tab, Preview"
	@echo "      Light sliders); reports $(OUT)/*_relight/*_texture_report.json; pictures"
	@echo "      $(OUT)/*-compare-low-sun.png (preview | Cycles Sun | difference x4)"
	@echo "      open $(OUT)/statue.blend (Vertex Transport Preview); report $(OUT)/statue_relight/"
	@echo "      open $(OUT)/room.blend (Material Edits: recolour the red wall, the light"
	@echo "      it throws follows); $(OUT)/room-edit-vs-cycles.png (preview before/after vs Cycles)"

WEB_STAMP := tests/web/node_modules/.installed

# The exported RTI page's browser test drives Debian's Chromium with playwright-core (from the
# npm registry, pinned in tests/web/package-lock.json; --prefer-offline: npm's cache serves it
# on a warm machine, where npm ci received 6.5 MB each time without it, measured 2026-12-02).
# Without npm the test skips (it fails under CI=true, where .ci/run installs both).
$(WEB_STAMP): tests/web/package.json tests/web/package-lock.json
	@if command -v npm >/dev/null 2>&1; then \
	  npm ci --prefix tests/web --no-audit --no-fund --silent --prefer-offline && \
	  touch $(WEB_STAMP); \
	else echo "make: npm not found; the web page test will skip" >&2; fi

## test: the full default test suite (core + real Blender/Cycles) on bpy 5.0.1; prints the 30
##   slowest tests and writes build/test-report.xml (`python3 tools/suite_cost.py
##   build/test-report.xml`: the cost by file); its time on 2 cores: docs/testing.md
test: $(STAMP) $(WEB_STAMP)
	@mkdir -p build; $(PY) -m pytest -q --durations=30 --junitxml=build/test-report.xml; rc=$$?; \
	if [ $$rc -eq 5 ]; then echo "make test: pytest collected no tests" >&2; fi; exit $$rc

test-core: $(STAMP)
	$(PY) -m pytest -q tests/core

## bench: the sweeps that print figures (not part of `make test`; ~1 h on 2 cores): the
##   transport bake vs the lobes presets on bumps, noise and statue+ground at demo size
##   (out/bench/transport_textures.*), the indirect term gathered by rays against the steerable
##   one (~10 min), relight bench --quick on all four scenes (JSON, CSV,
##   Pareto charts in out/bench), the CPCA comparison on statue and room (out/bench/cpca.*),
##   distributed and resumed bakes (1, 2, 4 local workers), the horizon-model experiment and
##   the material edits' transfer tensors on the demo room (~25 min of it, ~20 more for the
##   metal edits of glossy anchors), and the exports
##   of a balanced bumps bake (lightmaps, RTI, equal-coefficient comparison; ~5 min), the
##   thread settings of a bake, the up-front estimate against the bake at 256^2 and 512^2,
##   Mahajan's figures on a 65k-texel transport texture, and the real texture sizes: statue +
##   ground and the bumps at 1024^2 and 2048^2, each viewport against Cycles (~2 h more),
##   and the sun studies: hours against a ray count, two latitudes from a camera and the
##   year's maps against the Cycles renders they replace (~20 min)
bench: $(STAMP)
	mkdir -p $(OUT)/bench $(BLENDER_USER_RESOURCES)
	$(PY) benchmarks/bench_transport_textures.py --out $(OUT)/bench
	$(PY) benchmarks/bench_ray_direct.py --out $(OUT)/bench
	$(PY) benchmarks/bench_sun_path.py --out $(OUT)/bench
	$(PY) benchmarks/bench_indirect_gather.py --path --out $(OUT)/bench
	$(VENV)/bin/relight bench --quick --out $(OUT)/bench
	$(PY) benchmarks/bench_cpca.py --scenes statue,room --out $(OUT)/bench
	$(PY) benchmarks/bench_distributed.py
	$(PY) benchmarks/bench_horizon_model.py
	$(PY) benchmarks/bench_env_preview.py
	$(PY) benchmarks/bench_low_sun_floor.py
	$(PY) benchmarks/bench_file_features.py --json $(OUT)/bench/file_features.json
	$(PY) benchmarks/bench_export.py --out $(OUT)/bench
	$(PY) benchmarks/bench_materials.py --size demo
	$(PY) benchmarks/bench_materials.py --size demo --anchors roughness:0.4,0.8 \
	  --settings hemi:400:1.5/hemi:128/hemi:8@16
	$(PY) benchmarks/bench_threads.py --out $(OUT)/bench
	$(PY) benchmarks/bench_texel_cpca.py --out $(OUT)/bench
	$(PY) benchmarks/bench_viewports.py --scenes statue,bumps --resolutions 1024,2048
	$(PY) benchmarks/bench_gallery.py --out $(OUT)/bench/gallery --json $(OUT)/bench/gallery.json --camera all \
	  --truth-cache $(OUT)/bench/gallery-truths
	$(PY) benchmarks/bench_sun_study.py --json $(OUT)/bench/sun_study.json
	$(PY) benchmarks/bench_sun_study_places.py --out $(OUT)/bench/sun_study_places
	@# last: a timing check, which may fail on a busy machine after every figure above is out
	$(PY) benchmarks/bench_estimate.py --within 0.3

## bench-full: the standard (demo-size) sweeps behind the tables in docs/ (results.md and the
##   method pages) and the presets (~2 h): writes docs/bench (presets.json among it: copy it over
##   operators/bakes/presets.json to adopt them; tooling never writes into the package),
##   plus the deeper per-method benchmarks
bench-full: $(STAMP)
	mkdir -p $(OUT)/bench docs/bench $(BLENDER_USER_RESOURCES)
	$(VENV)/bin/relight bench --scene bumps --write-presets --out docs/bench
	$(VENV)/bin/relight bench --scene statue --scene room --out docs/bench
	$(PY) benchmarks/bench_cpca.py --scenes statue,room --out docs/bench
	$(PY) benchmarks/bench_steerable.py --json $(OUT)/bench/steerable.json
	$(PY) benchmarks/bench_texture_bake.py --presets draft,balanced
	$(PY) benchmarks/bench_transport.py --scenes statue,room --directions cube:16

## fuzz: damaged bake files and planted stages, journals, links and FIFOs against every reader
##   of bake files and the commit recovery, for an hour (FUZZ_SECONDS); counts and failures in
##   out/fuzz.json (docs/security.md; a bounded smoke of it runs in make test)
FUZZ_SECONDS ?= 3600
fuzz: $(STAMP)
	mkdir -p $(OUT) $(BLENDER_USER_RESOURCES)
	$(PY) devtools/fuzz_bake_files.py --bakes $(OUT)/fuzz-bakes --seconds $(FUZZ_SECONDS) \
	  --json $(OUT)/fuzz.json

## dist: validate and build the extension zips, one per platform, with Blender's own
##   extension tool (dist/relightable_textures-<version>-<platform>.zip). Needs only Python
##   >= 3.11 with pip, not the venv: BLENDER=/path/to/blender (4.2 or later) uses that
##   Blender's tool; else the venv's bpy where `make venv` has run; else the tool inside the
##   pinned bpy wheel in WHEELHOUSE (downloaded once, ~360 MB; nothing is installed). The
##   zips' wheels (requirements-wheels.txt) are downloaded with pip once, then kept in ~/.cache
dist:
	@py="$(PYTHON)"; [ ! -f $(STAMP) ] || py="$(PY)"; \
	set -x; "$$py" tools/extension_tool.py --output-dir dist --wheelhouse "$(WHEELHOUSE)" \
	  $(if $(BLENDER),--blender "$(BLENDER)")

## matrix: build the zips, install the linux-x64 one into each supported Blender (PyPI bpy
##   4.2.0 must refuse it, 4.2.13 ... newest 5.x must install, enable, bake) in venvs holding
##   only bpy, then run the full suite on the newest bpy and the version-sensitive subset on
##   5.2.3 LTS (both Python 3.13); cached under ~/.cache. MATRIX_ARGS passes options (.ci/run
##   passes --deadline)
matrix: $(STAMP) dist
	$(PY) tools/blender_matrix.py --markdown dist/blender-matrix.md $(MATRIX_ARGS)

clean:
	rm -rf $(OUT) dist build wheels .pytest_cache
