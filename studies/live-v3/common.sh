# Sourced by the study's scripts: where the study lives outside the repository, and its fixed commit.
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$HERE/../.." && pwd)"
COMMIT=1bc3ebf                     # the study's fixed commit, checked out (detached) in the worktree
WT=/work/wt/study                  # the worktree the study runs in
OUT=/work/studies/live-study-v3    # the study folder
CACHE=/work/cache-study            # its render cache

# Makes the worktree at COMMIT when it is missing; refuses (exit 2) one at another commit.
ensure_worktree() {
  [ -d "$WT" ] || git -C "$REPO" worktree add --detach "$WT" "$COMMIT"
  [ "$(git -C "$WT" rev-parse HEAD)" = "$(git -C "$REPO" rev-parse "$COMMIT")" ] \
    || { echo "worktree $WT is not at $COMMIT" >&2; exit 2; }
}

# The study's processes: its command and every process it started (Dask's spawned workers, the method fork
# servers), all of which run in the worktree.
study_pids() { for p in /proc/[0-9]*; do [ "$(readlink "$p/cwd" 2>/dev/null)" = "$WT" ] && basename "$p"; done; true; }
