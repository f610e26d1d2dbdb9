#!/usr/bin/env bash
# The static gates, run by .ci/run before the tests: ruff (the rule set in pyproject.toml's
# [tool.ruff]) over the whole tree, and mypy ([tool.mypy]: strict on the core package `emos`, a
# lighter level on emos.actors, emos.supervisor, emos.chaos and emos.tools). Exits non-zero on
# any finding of either; both always run, so one run shows everything.
#   scripts/lint.sh            both gates
#   scripts/lint.sh ruff|mypy  one of them
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
PY=${PYTHON:-python3}
which=${1:-all}
status=0

if [ "$which" = all ] || [ "$which" = ruff ]; then
  echo "lint: ruff check"
  $PY -m ruff check --quiet --output-format concise || status=1  # `ruff check` alone shows each in context
fi

if [ "$which" = all ] || [ "$which" = mypy ]; then
  # setup.py maps the top-level folders actors/, supervisor/, chaos/ and tools/ into the `emos`
  # namespace; mypy finds modules by folder and cannot follow that mapping (nor the editable
  # install's import hook). So it checks a tree of links in which emos/ holds every entry of
  # emos/ plus one link per mapped folder, and its paths are mapped back in the output. The tree
  # is rebuilt on every run, at one fixed place beside mypy's cache so that the cache (keyed on
  # file paths) stays valid from run to run. Two runs at once (two helpers, or a developer beside
  # CI) would delete each other's tree mid-check, so the whole mypy step holds an exclusive
  # flock on a lock file beside it: a second run waits for the first rather than breaking it.
  mkdir -p "$root/.mypy_cache"
  exec 9>"$root/.mypy_cache/emos-tree.lock"
  flock 9
  shadow=$root/.mypy_cache/emos-tree
  rm -rf "$shadow"
  mkdir -p "$shadow/emos"
  for entry in emos/*; do
    case "$entry" in */__pycache__) continue ;; esac
    ln -s "$root/$entry" "$shadow/emos/"
  done
  # ROOTS in setup.py is the one list of mapped folders: read it rather than repeat it here.
  mapped=$($PY -c 'import ast
tree = ast.parse(open("setup.py").read())
roots = next(ast.literal_eval(n.value) for n in ast.walk(tree)
             if isinstance(n, ast.Assign) and getattr(n.targets[0], "id", "") == "ROOTS")
for pkg, folder in roots.items():
    if pkg != "emos":
        print(pkg.split(".", 1)[1], folder)')
  subs=() unmap=(-e '')
  while read -r sub folder; do
    [ -d "$folder" ] || continue
    ln -s "$root/$folder" "$shadow/emos/$sub"
    subs+=("emos.$sub") unmap+=(-e "s#^emos/$sub/#$folder/#")
  done <<< "$mapped"
  echo "lint: mypy (emos ${subs[*]})"
  set +e
  (cd "$shadow" && $PY -m mypy --config-file "$root/pyproject.toml" --cache-dir "$root/.mypy_cache" -p emos) \
    | sed "${unmap[@]}"
  [ "${PIPESTATUS[0]}" = 0 ] || status=1
  set -e
  exec 9>&-  # release the lock
fi

[ $status = 0 ] && echo "lint: clean" || echo "lint: findings above (fix them; see pyproject.toml [tool.ruff] and [tool.mypy])" >&2
exit $status
