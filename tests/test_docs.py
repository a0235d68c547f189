"""Citations resolve: every ``docs/...`` file named in the package, the tests, README.md,
CONTRIBUTING.md and docs/ exists, every section ``§N`` cited with it is a heading of that file,
and every registered method has its page docs/methods/<name>.md."""
from __future__ import annotations

import re
from pathlib import Path

from dbench import registry

ROOT = Path(__file__).resolve().parent.parent
CITE = re.compile(r"(?<![A-Za-z0-9_/.])(docs/[A-Za-z0-9_./-]+?\.md)(?:,? ?§ ?(\d+))?")


def _texts():
    files = [*ROOT.joinpath("dbench").rglob("*.py"), *ROOT.joinpath("tests").rglob("*.py"),
             ROOT / "README.md", ROOT / "CONTRIBUTING.md", *ROOT.joinpath("docs").rglob("*.md")]
    for f in files:
        if "__pycache__" not in f.parts:
            yield f, f.read_text(encoding="utf-8")


def _sections(doc: Path) -> set[str]:
    """The top-level section numbers of a page: ``## 3. Title`` or ``## 3 Title`` → "3"."""
    heads = re.findall(r"^#{2,3} (?:§ ?)?(\d+)[.\s]", doc.read_text(encoding="utf-8"), re.M)
    return set(heads)


def test_every_cited_docs_file_and_section_exists():
    missing, no_section = [], []
    for f, text in _texts():
        for m in CITE.finditer(text):
            path, sec = m.group(1), m.group(2)
            doc = ROOT / path
            where = f"{f.relative_to(ROOT)}: {m.group(0)}"
            if not doc.is_file():
                missing.append(where)
            elif sec is not None and sec not in _sections(doc):
                no_section.append(where)
    assert missing == [] and no_section == []


#: a repository file named in the text: dbench/..., tests/..., scripts/... ending in .py
FILE = re.compile(r"(?<![A-Za-z0-9_/.<])((?:dbench|tests|scripts)/[A-Za-z0-9_/.-]+?\.py)\b")


def _names_other_code(text: str, at: int) -> bool:
    """A path of another project's code (``ProDen `scripts/analysis.py```), not this one's."""
    before = text[max(0, at - 40):at]
    return any(k in before for k in ("ProDen", "Falcor", "noisebase", "OIDN's", "Mitsuba's"))


def test_every_cited_source_file_exists():
    """Module and test paths named in docstrings, comments and docs exist (a moved file leaves
    no stale path behind)."""
    stale = sorted({f"{f.relative_to(ROOT)}: {m.group(1)}" for f, text in _texts()
                    for m in FILE.finditer(text) if not (ROOT / m.group(1)).is_file()
                    and not _names_other_code(text, m.start())})
    assert stale == []


def test_every_method_has_its_page():
    assert [n for n in registry.available()
            if not (ROOT / "docs" / "methods" / f"{n}.md").is_file()] == []


def test_the_package_cites_no_file_outside_the_repository():
    outside = re.compile(r"\.\./" + "shared|/work/" + "shared")
    assert [str(f.relative_to(ROOT)) for f, text in _texts() if outside.search(text)] == []


#: a README section cited by its name in double quotes after "README.md,", also across a
#: comment's line break
README_CITE = re.compile(r'README(?:\.md)?,?\s+(?:#\s*)?"([^"]+)"')


def test_every_cited_readme_section_exists():
    """A README section cited by name is one of its headings or the bold lead of a paragraph."""
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    heads = {h.strip() for h in re.findall(r"^#{2,4} (.+)$", readme, re.M)}
    leads = {b.strip().rstrip(".") for b in re.findall(r"\*\*([^*]+?)\*\*", readme)}
    unknown = []
    for f, text in _texts():
        for m in README_CITE.finditer(text):
            name = " ".join(re.sub(r"\n\s*#?", " ", m.group(1)).split())
            if not (name.rstrip(".") in leads or any(h.startswith(name) for h in heads)):
                unknown.append(f"{f.relative_to(ROOT)}: {name!r}")
    assert unknown == []


def test_published_results_cite_the_repository_docs():
    """The Markdown under results/ cites docs/, never the specification folder it was once
    written against (``spec/x.md``), which the repository does not hold."""
    stale = re.compile(r"(?<![\w/.])spec/\w+\.md")
    assert [str(f.relative_to(ROOT)) for f in ROOT.joinpath("results").rglob("*.md")
            if stale.search(f.read_text(encoding="utf-8"))] == []
