# Sourced by the bench scripts that compare a baseline commit with the working tree.
#
#   baseline_source DEFAULT_DIR REV
#
# Sets `dir` (BENCH_DIR, else DEFAULT_DIR, made absolute), `commit` (REV resolved) and `src`
# (the commit's source in `$dir/src-$commit`, unpacked from `git archive` once and kept).
baseline_source() {
    dir=${BENCH_DIR:-$1}
    mkdir -p "$dir"
    dir=$(cd "$dir" && pwd)
    commit=$(git rev-parse "$2")
    src="$dir/src-$commit"
    if [ ! -d "$src" ]; then
        mkdir -p "$src.tmp"
        git archive "$commit" | tar -x -C "$src.tmp"
        mv "$src.tmp" "$src"
    fi
}
