#!/usr/bin/env python3
"""The layers of src/ only depend downwards: core includes nothing of io,
job, lib or cli; io nothing of job, lib or cli; job nothing of lib or cli;
lib nothing of cli; cli nothing of lib. A quoted include is resolved the way
the build resolves it: to the layer directory that holds that header.

Also: no circle of includes inside core (a file counts as the header it
implements), and lit fog (light.c, lit*.c) reads no model's internals.

Usage: layers_check.py SRC_DIR"""
import os
import re
import sys

ORDER = ["core", "io", "job", "lib", "cli"]
# what each layer may include besides itself
ALLOWED = {"core": set(), "io": {"core"}, "job": {"core", "io"}, "lib": {"core", "io", "job"},
           "cli": {"core", "io", "job"}}


def main(src):
    owner = {}
    for layer in ORDER:
        for root, _, files in os.walk(os.path.join(src, layer)):
            for f in files:
                if f.endswith((".h", ".hpp")):
                    owner.setdefault(f, layer)
    bad = []
    checked = 0
    for layer in ORDER:
        for root, _, files in os.walk(os.path.join(src, layer)):
            for f in files:
                if not f.endswith((".c", ".cpp", ".h", ".hpp")):
                    continue
                path = os.path.join(root, f)
                for n, line in enumerate(open(path, errors="replace"), 1):
                    m = re.match(r'\s*#\s*include\s*"([^"]+)"', line)
                    if not m:
                        continue
                    checked += 1
                    name = os.path.basename(m.group(1))
                    if os.path.exists(os.path.join(root, m.group(1))):
                        continue  # beside the includer: its own layer
                    dep = owner.get(name)
                    if dep is None:
                        continue  # generated (version.h) or a system header in quotes
                    if dep != layer and dep not in ALLOWED[layer]:
                        bad.append("%s:%d: %s (%s) includes %s of %s" %
                                   (os.path.relpath(path, src), n, layer, f, name, dep))
    for b in bad:
        print(b)
    print("layers: %d includes checked, %d up the layers" % (checked, len(bad)))
    other = core_cycles(src) + lit_owns_no_model(src)
    for b in other:
        print(b)
    return 1 if bad or other else 0


def core_cycles(src):
    """Includes inside core form no circle: a file X.c counts as its header
    X.h (it implements it), so light.c including lit.h, which includes
    scene.h, which includes light.h, is a circle."""
    core = os.path.join(src, "core")
    graph = {}
    for f in os.listdir(core):
        if not f.endswith((".c", ".h")):
            continue
        # a file counts as the header it implements; a family's private
        # header (lit_int.h) as its family's (lit.h)
        node = f[:-2].replace("_int", "") + ".h"
        for line in open(os.path.join(core, f), errors="replace"):
            m = re.match(r'\s*#\s*include\s*"([^"/]+)"', line)
            inc = m.group(1).replace("_int.h", ".h") if m else None
            if m and os.path.exists(os.path.join(core, m.group(1))) and inc != node:
                graph.setdefault(node, set()).add(inc)
    bad, state = [], {}

    def visit(n, path):
        state[n] = 1
        for d in sorted(graph.get(n, ())):
            if state.get(d) == 1:
                bad.append("core: include circle: " + " -> ".join(path[path.index(d):] + [d]))
            elif d not in state:
                visit(d, path + [d])
        state[n] = 2

    for n in sorted(graph):
        if n not in state:
            visit(n, [n])
    print("core: %d files in the include graph, %d circles" % (len(graph), len(bad)))
    return bad


def lit_owns_no_model(src):
    """Lit fog knows no model's internals (issue 43): no identity test of a
    model and no parameter slot read by number in light.c or lit*.c; the
    models answer through their hooks (uniform, strata, sun)."""
    core = os.path.join(src, "core")
    pat = re.compile(r"model [=!]= &ef_fog_|(->|\.)p\[[0-9]")
    bad = []
    for f in sorted(os.listdir(core)):
        if f == "light.c" or (f.startswith("lit") and f.endswith((".c", ".h"))):
            for n, line in enumerate(open(os.path.join(core, f), errors="replace"), 1):
                if pat.search(line):
                    bad.append("core/%s:%d: lit fog reads a model's internals: %s" %
                               (f, n, line.strip()))
    print("lit: %d reads of a model's internals" % len(bad))
    return bad


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
