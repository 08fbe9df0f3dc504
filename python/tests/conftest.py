"""Shared fixtures: the repository, its bundled sample, and the CLIs to compare against.

The CLIs are the workspace's release binaries: `$QBRICKS_BIN_DIR`, else
`$CARGO_TARGET_DIR/release`, else `<repo>/target/release`; built with cargo when missing,
so the tests work from a clean clone.
"""

import os
import pathlib
import subprocess

import pytest

REPO = pathlib.Path(__file__).resolve().parents[2]
SAMPLE = REPO / "data" / "wake_small.qbk"
SAMPLE_VDB = REPO / "data" / "wake_small.vdb"


def _bin_dir() -> pathlib.Path:
    if os.environ.get("QBRICKS_BIN_DIR"):
        return pathlib.Path(os.environ["QBRICKS_BIN_DIR"])
    target = os.environ.get("CARGO_TARGET_DIR")
    target = pathlib.Path(target) if target else REPO / "target"
    if not target.is_absolute():
        target = REPO / target
    return target / "release"


@pytest.fixture(scope="session")
def cli():
    """Runs `qbricks-view` or `qbricks-bake` with arguments; returns stdout (bytes)."""
    d = _bin_dir()
    names = ("qbricks-view", "qbricks-bake")
    if not all((d / n).exists() for n in names):
        subprocess.run(
            ["cargo", "build", "--release", "-p", "qbricks-viewer", "--no-default-features",
             "-p", "qbricks-preprocess", "--bins"],
            cwd=REPO, check=True,
        )

    def run(name, *args, cwd=None):
        r = subprocess.run([str(d / name), *map(str, args)], cwd=cwd or REPO,
                           capture_output=True)
        if r.returncode != 0:
            raise AssertionError(f"{name} {args}: {r.stderr.decode()}")
        return r.stdout

    return run


@pytest.fixture(scope="session")
def ds():
    import qbricks
    return qbricks.open(SAMPLE)
