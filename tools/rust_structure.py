#!/usr/bin/env python3
"""Two structure checks on a Rust crate's sources (comments and strings stripped, inline
`#[cfg(test)] mod` blocks left out):

  rust_structure.py sizes LIMIT FILE...   non-test functions longer than LIMIT lines
  rust_structure.py cycles SRC [FILTER]   file-level import cycles (strongly connected
                                          components of the `crate::`/`super::`/`self::`/child
                                          paths each file names), those involving FILTER
  rust_structure.py floors SRC PREFIX     the files under PREFIX by floor (each names only
                                          files of lower floors)

In the cycle check a parent module's references to its own descendants (its `mod` declarations
and re-exports, the module's face) and lib.rs are not counted; a child's use of its parent is.
"""
import os
import re
import sys

def strip(src):
    out = []; i = 0; n = len(src)
    while i < n:
        c = src[i]
        if src.startswith('//', i):
            j = src.find('\n', i); j = n if j < 0 else j
            out.append(' ' * (j - i)); i = j; continue
        if src.startswith('/*', i):
            depth = 1; j = i + 2
            while j < n and depth:
                if src.startswith('/*', j): depth += 1; j += 2
                elif src.startswith('*/', j): depth -= 1; j += 2
                else: j += 1
            out.append(re.sub(r'[^\n]', ' ', src[i:j])); i = j; continue
        m = re.match(r'r(#*)"', src[i:i+10])
        if m and (i == 0 or not (src[i-1].isalnum() or src[i-1] == '_')):
            hashes = m.group(1); end = '"' + hashes
            j = src.find(end, i + len(m.group(0)))
            j = n if j < 0 else j + len(end)
            out.append(re.sub(r'[^\n]', ' ', src[i:j])); i = j; continue
        if c == '"':
            j = i + 1
            while j < n and src[j] != '"':
                j += 2 if src[j] == '\\' else 1
            j += 1
            out.append(re.sub(r'[^\n]', ' ', src[i:j])); i = j; continue
        if c == "'":
            m = re.match(r"'(\\.[^']*|[^\\'])'", src[i:i+12])
            if m:
                out.append(' ' * len(m.group(0))); i += len(m.group(0)); continue
        out.append(c); i += 1
    return ''.join(out)

def functions(path):
    src = strip(open(path).read())
    lines = src.split('\n')
    # find test module ranges: #[cfg(test)] followed by mod X {
    test_ranges = []
    for m in re.finditer(r'#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{', src):
        start = m.end() - 1
        depth = 0; j = start
        while j < len(src):
            if src[j] == '{': depth += 1
            elif src[j] == '}':
                depth -= 1
                if depth == 0: break
            j += 1
        test_ranges.append((m.start(), j))
    res = []
    for m in re.finditer(r'\bfn\s+(\w+)', src):
        pos = m.start()
        if any(a <= pos <= b for a, b in test_ranges): continue
        # find body brace: first '{' or ';' at paren depth 0
        j = m.end(); par = 0; ang = 0
        while j < len(src):
            ch = src[j]
            if ch in '([': par += 1
            elif ch in ')]': par -= 1
            elif ch == ';' and par == 0: j = -1; break
            elif ch == '{' and par == 0: break
            j += 1
        if j < 0 or j >= len(src): continue
        depth = 0; k = j
        while k < len(src):
            if src[k] == '{': depth += 1
            elif src[k] == '}':
                depth -= 1
                if depth == 0: break
            k += 1
        l0 = src.count('\n', 0, pos) + 1; l1 = src.count('\n', 0, k) + 1
        res.append((l1 - l0 + 1, m.group(1), path, l0))
    return res


def fn_sizes(limit, paths):
    allf = []
    for p in paths:
        allf += functions(p)
    big = sorted([f for f in allf if f[0] > limit], reverse=True)
    for f in big:
        print(f"{f[0]:5d} {f[1]} {f[2]}:{f[3]}")
    print(f"{len(big)} non-test functions over {limit} lines (of {len(allf)})")

def graph(root):
    """File-level edges of the crate under `root`: each .rs file (relative path) to the files
    whose modules it names. A parent module's references to its own descendants (declarations,
    re-exports: the module's face) are not counted, nor lib.rs's; a child's use of its parent
    is."""
    files = {}
    for d, _, fs in os.walk(root):
        for f in fs:
            if f.endswith(".rs"):
                p = os.path.join(d, f)
                files[os.path.relpath(p, root)] = p

    def modpath(rel):
        parts = rel[:-3].split("/")
        if parts[-1] in ("mod", "lib", "main"):
            parts = parts[:-1]
        return parts

    mods = {tuple(modpath(r)): r for r in files}

    def resolve(path):
        # The longest prefix that is a module file.
        for k in range(len(path), -1, -1):
            if tuple(path[:k]) in mods:
                return mods[tuple(path[:k])]
        return None

    edges = {}
    for rel, p in files.items():
        src = strip_tests(strip(open(p).read()))
        me = modpath(rel)
        dep = set()
        for m in re.finditer(r"\b(crate|super|self)((?:::\w+)*)(::\{([^;]*?)\}|::\*)?", src):
            if not m.group(2) and not m.group(3):
                continue
            base, rest = m.group(1), [x for x in m.group(2).split("::") if x]
            if base == "crate":
                path = rest
            elif base == "self":
                path = me + rest
            else:
                parent = me[:-1]
                while rest and rest[0] == "super":
                    parent, rest = parent[:-1], rest[1:]
                path = parent + rest
            targets = [path]
            for item in (m.group(4) or "").split(","):
                item = item.strip().split(" ")[0]
                if item and item != "self" and not item.startswith("{"):
                    targets.append(path + [x for x in item.split("::") if x and x != "*"])
            for t in targets:
                r = resolve(t)
                if r and r != rel:
                    dep.add(r)
        # Paths from a child module of this file (`candidates::Candidates` in a mod.rs).
        for m in re.finditer(r"(?<![:\w])(\w+)::", src):
            t = tuple(me + [m.group(1)])
            if m.group(1) not in ("crate", "super", "self") and t in mods and mods[t] != rel:
                dep.add(mods[t])
        edges[rel] = dep

    def is_desc(parent, child):
        pm, cm = modpath(parent), modpath(child)
        face = parent.endswith("mod.rs") or parent == "lib.rs"
        return face and len(cm) > len(pm) and cm[: len(pm)] == pm

    return {v: {w for w in ws if not is_desc(v, w) and w != "lib.rs"} for v, ws in edges.items()}


def strip_tests(src):
    """`src` without its inline `#[cfg(test)] mod ... { }` blocks."""
    pat = r"#\[cfg\(test\)\]\s*(pub(\([^)]*\))?\s+)?mod\s+\w+\s*\{"
    for m in reversed(list(re.finditer(pat, src))):
        depth, j = 0, m.end() - 1
        while j < len(src):
            if src[j] == "{":
                depth += 1
            elif src[j] == "}":
                depth -= 1
                if depth == 0:
                    break
            j += 1
        src = src[: m.start()] + src[j + 1 :]
    return src


def sccs(edges):
    """Strongly connected components (Tarjan)."""
    idx, low, st, on, out, c = {}, {}, [], set(), [], [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        idx[v] = low[v] = c[0]
        c[0] += 1
        st.append(v)
        on.add(v)
        for w in edges[v]:
            if w not in idx:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], idx[w])
        if low[v] == idx[v]:
            comp = []
            while True:
                w = st.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            out.append(comp)

    for v in edges:
        if v not in idx:
            visit(v)
    return out


def cycles(root, flt=None):
    edges = graph(root)
    found = 0
    for comp in sccs(edges):
        if len(comp) > 1 and (not flt or any(flt in x for x in comp)):
            found += 1
            print(len(comp), sorted(comp))
            for v in sorted(comp):
                print("   ", v, "->", sorted(w for w in edges[v] if w in comp))
    print(f"{found} import cycle(s)" + (f" involving {flt}" if flt else ""))


def floors(root, prefix):
    """The files under `prefix` by floor: each looks only at files of lower floors."""
    edges = graph(root)
    inside = {v: {w for w in ws if w.startswith(prefix)} for v, ws in edges.items() if v.startswith(prefix)}
    floor = {}

    def level(v, seen=()):
        if v in floor:
            return floor[v]
        if v in seen:
            raise SystemExit(f"cycle through {v}")
        floor[v] = 1 + max((level(w, seen + (v,)) for w in inside[v]), default=-1)
        return floor[v]

    for v in inside:
        level(v)
    for k in range(max(floor.values()) + 1):
        print(k, " ".join(sorted(v[len(prefix):] for v in floor if floor[v] == k)))


if __name__ == "__main__":
    if len(sys.argv) >= 3 and sys.argv[1] == "sizes":
        fn_sizes(int(sys.argv[2]), sys.argv[3:])
    elif len(sys.argv) >= 3 and sys.argv[1] == "cycles":
        cycles(sys.argv[2], sys.argv[3] if len(sys.argv) > 3 else None)
    elif len(sys.argv) == 4 and sys.argv[1] == "floors":
        floors(sys.argv[2], sys.argv[3])
    else:
        sys.exit(__doc__)
