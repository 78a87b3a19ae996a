#!/usr/bin/env python3
"""Checks the README and the book under docs/: every relative link points
at a file that exists, every #anchor at a heading of its page (anchors as
mdBook and GitHub make them), every page of docs/ is in SUMMARY.md, and
every Rust, Python and C++ example is a tested one: its block follows a
`<!-- example: FILE:NAME -->` line and equals, line for line, the code
between `ANCHOR: NAME` and `ANCHOR_END: NAME` in FILE (a test, run by
CI), dedented. Exits 1 naming each problem."""

import re
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"!?\[(?:[^\]\[]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def slug(heading: str) -> str:
    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading.strip().lstrip("#").strip())
    text = text.lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def prose(path: Path):
    """The lines outside fenced code, with their numbers."""
    fence = False
    for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
        if line.lstrip().startswith("```"):
            fence = not fence
            continue
        if not fence:
            yield n, line


def anchors(path: Path) -> set:
    seen = {}
    out = set()
    for _, line in prose(path):
        if re.match(r"^#{1,6} ", line):
            s = slug(line)
            k = seen.get(s, 0)
            out.add(s if k == 0 else f"{s}-{k}")
            seen[s] = k + 1
    return out


def tested_region(path: Path, name: str):
    """The code between a file's ANCHOR lines for `name`, dedented."""
    text = path.read_text(encoding="utf-8")
    m = re.search(
        rf"^[ \t]*(?://|#) ANCHOR: {re.escape(name)}\n(.*?)^[ \t]*(?://|#) ANCHOR_END: {re.escape(name)}\n",
        text,
        re.S | re.M,
    )
    return textwrap.dedent(m.group(1)) if m else None


def examples(page: Path, errors: list):
    """Checks that each Rust, Python or C++ block of `page` is a tested example."""
    lines = page.read_text(encoding="utf-8").splitlines()
    i = 0
    while i < len(lines):
        fence = re.match(r"^```(\w+)", lines[i])
        if not fence:
            i += 1
            continue
        end = next((j for j in range(i + 1, len(lines)) if lines[j].startswith("```")), len(lines))
        if fence.group(1) in ("rust", "python", "cpp"):
            where = f"{page.relative_to(ROOT)}:{i + 1}"
            marker = re.match(r"^<!-- example: (\S+):(\w+) -->$", lines[i - 1]) if i > 0 else None
            if not marker:
                errors.append(f"{where}: a {fence.group(1)} block without an <!-- example: FILE:NAME --> line")
            else:
                source = (page.parent / marker.group(1)).resolve()
                want = tested_region(source, marker.group(2)) if source.exists() else None
                got = "\n".join(lines[i + 1 : end]) + "\n"
                if want is None:
                    errors.append(f"{where}: no ANCHOR {marker.group(2)} in {marker.group(1)}")
                elif want != got:
                    errors.append(f"{where}: differs from {marker.group(1)}:{marker.group(2)}")
        i = end + 1


def main() -> int:
    pages = [ROOT / "README.md"] + sorted((ROOT / "docs").rglob("*.md"))
    errors = []
    for page in pages:
        for n, line in prose(page):
            line = re.sub(r"`[^`]*`", "", line)
            for target in LINK.findall(line):
                if re.match(r"^[a-z][a-z0-9+.-]*:", target):
                    continue
                file, _, anchor = target.partition("#")
                dest = (page.parent / file).resolve() if file else page
                where = f"{page.relative_to(ROOT)}:{n}: {target}"
                if not dest.exists():
                    errors.append(f"{where}: no such file")
                elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                    errors.append(f"{where}: no heading with that anchor")
    for page in pages:
        examples(page, errors)
    summary = (ROOT / "docs" / "SUMMARY.md").read_text(encoding="utf-8")
    listed = {(ROOT / "docs" / t).resolve() for t in re.findall(r"\]\(([^)#]+\.md)\)", summary)}
    for page in sorted((ROOT / "docs").rglob("*.md")):
        if page.name != "SUMMARY.md" and page.resolve() not in listed:
            errors.append(f"{page.relative_to(ROOT)}: not in docs/SUMMARY.md")
    for e in errors:
        print(e, file=sys.stderr)
    print(f"check_docs: {len(pages)} pages, {len(errors)} problems", file=sys.stderr)
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
