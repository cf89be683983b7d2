# Sourced by the chapter scripts. once DIR COMMAND...: run COMMAND --out DIR --quiet, unless DIR holds a run whose
# summary says "completed" (kept: re-running a chapter script resumes where it stopped).
once() {
  local dir=$1; shift
  if grep -qs '"status": "completed"' "$dir/summary.json"; then echo "kept $dir"; return; fi
  rm -rf "$dir"
  "$@" --out "$dir" --quiet
}
