# Sourced by scripts/bench-against and scripts/bench-client-against: builds one target of
# another commit in a worktree of its own, build-against/<commit>/ with its build tree inside
# (once per commit), laid out as this checkout is and compiled with this build's flags, so that
# ccache finds the files the commit shares with it.
#
#   build_commit_target PROGRAM SHA SHORT TARGET    run from the checkout's root; BUILD_DIR set
#   (sets COMMIT_DIR to the worktree; exits 1, naming the log, when configuring or building fails)
build_commit_target() {
  local program=$1 sha=$2 short=$3 target=$4
  COMMIT_DIR=build-against/$short
  [ -x "$COMMIT_DIR/build/bin/$target" ] && return 0
  echo "$program: building $short's $target in $COMMIT_DIR (once per commit)"
  if [ ! -d "$COMMIT_DIR/.git" ] && [ ! -f "$COMMIT_DIR/.git" ]; then
    git worktree add --force --detach "$COMMIT_DIR" "$sha" >/dev/null
  fi
  local launcher=()
  if command -v ccache >/dev/null; then  # as scripts/setup: paths relative to the checkout
    export CCACHE_BASEDIR=$PWD CCACHE_NOHASHDIR=1
    launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache)
  fi
  # -Werror as this checkout's build has it (CI's): compile lines that differ share nothing in
  # ccache (without it, a cold CI run built the whole server again: 134 s against 11).
  local werror=OFF
  grep -q '^CLOUDCAST_WERROR:BOOL=ON$' "$BUILD_DIR/CMakeCache.txt" 2>/dev/null && werror=ON
  cmake -S "$COMMIT_DIR" -B "$COMMIT_DIR/build" -G Ninja -DCMAKE_BUILD_TYPE=Release \
    -DCLOUDCAST_WERROR=$werror "${launcher[@]}" >"$COMMIT_DIR/configure.log" 2>&1 || {
    echo "$program: configuring $short failed; see $COMMIT_DIR/configure.log" >&2
    exit 1
  }
  cmake --build "$COMMIT_DIR/build" -j "$(nproc)" --target "$target" >"$COMMIT_DIR/build.log" 2>&1 || {
    echo "$program: building $short's $target failed; see $COMMIT_DIR/build.log" >&2
    exit 1
  }
}
