#!/usr/bin/env python3
"""The layers of src/ only depend downwards: core includes nothing of io,
job, lib or cli; io nothing of job, lib or cli; job nothing of lib or cli;
lib nothing of cli; cli nothing of lib. A quoted include is resolved the way
the build resolves it: to the layer directory that holds that header.

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
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
