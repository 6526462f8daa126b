#!/usr/bin/env python3
"""Which units `cargo test --release` would build again after
`cargo run --release` built its own: the README's two commands on a fresh
clone should compile each dependency once.

Reads the two unit graphs, `cargo build -p topspin --bin topspin` (what
`cargo run` builds) and `cargo test --no-run`, without compiling anything
(`--unit-graph` is unstable, hence RUSTC_BOOTSTRAP=1), and prints each
library unit of the test build that the run build also has, with the same
profile, under another identity (features, or a dependency's identity).
Exit code 1 when there is one.

    python3 tools/compile_once.py
"""
import json
import os
import subprocess
import sys


def unit_graph(*args):
    env = dict(os.environ, RUSTC_BOOTSTRAP="1")
    out = subprocess.run(
        ["cargo", *args, "--release", "--unit-graph", "-Z", "unstable-options"],
        env=env, check=True, capture_output=True, text=True,
    ).stdout
    return json.loads(out)["units"]


def identities(units):
    memo = {}

    def ident(i):
        if i not in memo:
            u = units[i]
            memo[i] = hash((
                u["pkg_id"], u["target"]["name"], u["mode"],
                tuple(sorted(u["features"])),
                json.dumps(u["profile"], sort_keys=True), u.get("platform"),
                tuple(sorted(ident(d["index"]) for d in u["dependencies"])),
            ))
        return memo[i]

    out = {}
    for i, u in enumerate(units):
        if u["target"]["kind"] in (["bin"], ["test"], ["bench"], ["example"]):
            continue
        # The same crate for the host (build scripts, proc macros) and for
        # the target is two units in any one build, not a rebuild.
        out[ident(i)] = (u["pkg_id"], u["target"]["name"], u["mode"],
                         json.dumps(u["profile"], sort_keys=True))
    return out


def main():
    run = identities(unit_graph("build", "-p", "topspin", "--bin", "topspin"))
    test = identities(unit_graph("test", "--no-run"))
    names = set(run.values())
    again = sorted({v for k, v in test.items() if k not in run and v in names})
    for pkg, target, mode, _ in again:
        print(f"built again: {target} ({pkg}, {mode})")
    print(f"{len(again)} units built twice")
    return 1 if again else 0


if __name__ == "__main__":
    sys.exit(main())
