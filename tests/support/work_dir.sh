# work_dir.sh: the scratch folder of a shell test, sourced by tests/*/*.sh.
#   begin_work_dir BUILD_DIR NAME
# makes BUILD_DIR/test-tmp/NAME afresh, enters it, and sets $work to it. A test that
# passes (or skips) removes it on exit: the large tests write hundreds of megabytes,
# and CI runs every test in several builds on one disk. A test that fails keeps it,
# to be looked at.
begin_work_dir() {
    work=$1/test-tmp/$2
    rm -rf "$work" && mkdir -p "$work" && cd "$work"
    trap 'rc=$?; cd /; [ "$rc" -ne 0 ] && [ "$rc" -ne 77 ] || rm -rf "$work"' EXIT
}
