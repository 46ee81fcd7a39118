#!/usr/bin/env python3
"""Function lengths in the workspace's Rust code (issue 55's figures).

    checks/fn_lengths.py [--over N] [--list] [PATH...]

Counts every `fn` with a body, from its `fn` line to its closing brace,
in the .rs files under the given paths (default: src and crates). Test
code is left out: files under a `tests/` folder, benches, examples, and
the items after `#[cfg(test)]` or `#[test]`. Prints the number of
non-test functions, how many are over 100 and over 150 lines (all, in
crates/service + src, and outside crates/eval), and with --list each
function over --over lines (default 100), longest first.

Comments, strings and char literals are blanked before the braces are
counted, so a brace in a string or a doc comment does not count.
"""

import os
import re
import sys


def blank(src: str) -> str:
    """The source with comments, strings and chars replaced by spaces,
    newlines kept (so line numbers stay)."""
    out = []
    i, n = 0, len(src)
    while i < n:
        c = src[i]
        if src.startswith("//", i):
            j = src.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif src.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if src.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif src.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif re.match(r'b?r#*"', src[i:i + 40]) and (i == 0 or not (src[i - 1].isalnum() or src[i - 1] == "_")):
            m = re.match(r'(b?r)(#*)"', src[i:])
            close = '"' + m.group(2)
            j = src.find(close, i + m.end())
            j = n if j < 0 else j + len(close)
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == '"' or (c == "b" and src.startswith('b"', i) and (i == 0 or not src[i - 1].isalnum())):
            j = i + (2 if c == "b" else 1)
            while j < n and src[j] != '"':
                j += 2 if src[j] == "\\" else 1
            j += 1
            out.append(re.sub(r"[^\n]", " ", src[i:j]))
            i = j
        elif c == "'":
            # A char literal ('a', '\n', '\u{..}', '{') or a lifetime ('a).
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\.|[^\\'])'", src[i:])
            if m:
                out.append(" " * m.end())
                i += m.end()
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching(code: str, open_at: int) -> int:
    depth = 0
    for j in range(open_at, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code) - 1


def test_ranges(code: str):
    """Character ranges of items behind #[cfg(test)] or #[test]."""
    ranges = []
    for m in re.finditer(r"#\[\s*(cfg\(\s*test\s*\)|test|tokio::test[^\]]*)\s*\]", code):
        # The item after the attribute: up to its first `{` (or `;`).
        j = m.end()
        k = re.compile(r"[{;]").search(code, j)
        if not k:
            continue
        end = matching(code, k.start()) if code[k.start()] == "{" else k.start()
        ranges.append((m.start(), end))
    return ranges


FN = re.compile(r"\bfn\s+([A-Za-z_][A-Za-z0-9_]*)")


def functions(path: str):
    src = open(path, encoding="utf-8").read()
    code = blank(src)
    tests = test_ranges(code)
    for m in FN.finditer(code):
        # The body: the first `{` after the signature at paren depth 0,
        # unless a `;` comes first (a declaration without a body).
        depth, j = 0, m.end()
        while j < len(code):
            ch = code[j]
            if ch == "(" or ch == "[":
                depth += 1
            elif ch == ")" or ch == "]":
                depth -= 1
            elif depth <= 0 and ch in "{;":
                break
            j += 1
        if j >= len(code) or code[j] == ";":
            continue
        end = matching(code, j)
        first = code.count("\n", 0, m.start()) + 1
        last = code.count("\n", 0, end) + 1
        is_test = any(a <= m.start() <= b for a, b in tests)
        yield m.group(1), first, last - first + 1, is_test


def rust_files(roots):
    for root in roots:
        if os.path.isfile(root):
            yield root
            continue
        for d, dirs, files in os.walk(root):
            dirs[:] = [x for x in dirs if x not in ("target", ".git") and not x.startswith(".")]
            for f in files:
                if f.endswith(".rs"):
                    yield os.path.join(d, f)


def is_test_file(path: str) -> bool:
    parts = path.replace("\\", "/").split("/")
    return any(p in ("tests", "benches", "examples") for p in parts[:-1]) or parts[-1] in ("tests.rs",)


def main(argv):
    over, listing, roots = 100, False, []
    i = 0
    while i < len(argv):
        if argv[i] == "--over":
            over = int(argv[i + 1])
            i += 2
            continue
        if argv[i] == "--list":
            listing = True
        else:
            roots.append(argv[i])
        i += 1
    roots = roots or ["src", "crates"]
    rows = []
    for path in sorted(rust_files(roots)):
        if is_test_file(path):
            continue
        for name, line, length, is_test in functions(path):
            if not is_test:
                rows.append((length, path, line, name))

    def count(pred, n):
        return sum(1 for r in rows if pred(r[1]) and r[0] > n)

    def service_or_src(p):
        return p.startswith("src/") or p.startswith("crates/service/")

    def not_eval(p):
        return not p.startswith("crates/eval/")

    print(f"non-test functions: {len(rows)}")
    for label, pred in (("all", lambda p: True), ("crates/service + src", service_or_src), ("outside crates/eval", not_eval)):
        print(f"{label:22} over 100: {count(pred, 100):3}   over 150: {count(pred, 150):3}")
    if listing:
        for length, path, line, name in sorted(rows, reverse=True):
            if length > over:
                print(f"{length:5}  {path}:{line}  {name}")


if __name__ == "__main__":
    main(sys.argv[1:])
