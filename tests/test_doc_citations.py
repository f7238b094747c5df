"""Every section a comment or a document cites resolves inside this repository: ``docs/NAME.md
§S`` to a heading S of that file, a bare ``§S`` (the solver's sections, 0-H) and ``Appendix
N.M`` in the package to docs/solver.md's heading and numbered item. Someone who clones only
this repository can follow every citation (issue 15: the specification inside the repository)."""
import pathlib
import re

ROOT = pathlib.Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
# a numbered heading: "### D.5 Angle limit and D.6 ...", "## 0. Conventions", "### 7. Compile time"
HEADING = re.compile(r"^#+\s+(?:Appendix\s+)?([0-9A-H](?:\.\d+)?)\.?\s")
SECTION_IN_HEADING = re.compile(r"\b([A-H]\.\d+)\b")
CITED_IN_DOC = re.compile(r"docs/([a-z_-]+)\.md\s+§\s*([0-9A-Z](?:\.\d+)?)")
BARE = re.compile(r"(?<![\w.])§\s*([0-9A-H](?:\.\d+)?)")
APPENDIX = re.compile(r"Appendix\s+(\d+)(?:\.(\d+))?")


def sections(path: pathlib.Path) -> set:
    """The section numbers the headings of a markdown file name (with ``D.6`` of a heading that
    covers two sections)."""
    found = set()
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            continue
        m = HEADING.match(line)
        if m:
            found.add(m.group(1))
        found.update(SECTION_IN_HEADING.findall(line))
    return found


def appendix_items(path: pathlib.Path) -> dict:
    """Appendix number -> the numbers of its top-level numbered items."""
    items, current = {}, None
    for line in path.read_text(encoding="utf-8").splitlines():
        m = re.match(r"^##\s+Appendix\s+(\d+)\.", line)
        if m:
            current = m.group(1)
            items[current] = set()
        elif line.startswith("## "):
            current = None
        elif current is not None:
            n = re.match(r"^(\d+)\.\s", line)
            if n:
                items[current].add(n.group(1))
    return items


def _sources():
    yield from sorted((ROOT / "magica_py").rglob("*.py"))
    yield from sorted(DOCS.glob("*.md"))


def test_every_cited_section_of_a_named_document_is_one_of_its_headings():
    known = {p.stem: sections(p) for p in DOCS.glob("*.md")}
    missing = []
    for path in _sources():
        for m in CITED_IN_DOC.finditer(path.read_text(encoding="utf-8")):
            doc, section = m.group(1), m.group(2)
            if doc not in known:
                missing.append(f"{path.relative_to(ROOT)}: docs/{doc}.md does not exist")
            elif section not in known[doc] and section != "N":   # "§N": the notation explained
                missing.append(f"{path.relative_to(ROOT)}: docs/{doc}.md has no section {section}")
    assert not missing, "\n".join(missing)


def test_every_bare_solver_section_in_the_package_is_a_heading_of_solver_md():
    known = sections(DOCS / "solver.md")
    missing = []
    for path in sorted((ROOT / "magica_py").rglob("*.py")):
        for line in path.read_text(encoding="utf-8").splitlines():
            other = re.search(r"docs/(?!solver)[a-z_-]+\.md", line) or "glTF" in line
            for m in BARE.finditer(line):
                section = m.group(1)
                if other and "." not in section or other and section[0].isdigit():
                    continue   # a section of the other document the line names
                if section not in known:
                    missing.append(f"{path.relative_to(ROOT)}: §{section}")
    assert not missing, "docs/solver.md has no heading for:\n" + "\n".join(missing)


def test_every_cited_appendix_item_exists_in_solver_md():
    items = appendix_items(DOCS / "solver.md")
    missing = []
    for path in sorted((ROOT / "magica_py").rglob("*.py")):
        for m in APPENDIX.finditer(path.read_text(encoding="utf-8")):
            appendix, item = m.group(1), m.group(2)
            if appendix not in items or (item is not None and item not in items[appendix]):
                missing.append(f"{path.relative_to(ROOT)}: {m.group(0)}")
    assert not missing, "docs/solver.md has no:\n" + "\n".join(missing)


def test_the_citation_checks_see_a_missing_section():
    """The patterns match the forms the code uses, so a citation of a section that does not
    exist is caught (the tests above would pass vacuously on a pattern that matches nothing)."""
    assert CITED_IN_DOC.search("(docs/tech-notes.md §7)").groups() == ("tech-notes", "7")
    assert BARE.search("Angle limit (docs/solver.md §D.5) and").group(1) == "D.5"
    assert APPENDIX.search("(Appendix 3.11: a guard)").groups() == ("3", "11")
    assert "D.6" in sections(DOCS / "solver.md") and "Z.1" not in sections(DOCS / "solver.md")
    assert "16" in appendix_items(DOCS / "solver.md")["3"]
    assert "7" in sections(DOCS / "tech-notes.md") and "2" not in sections(DOCS / "tech-notes.md")
