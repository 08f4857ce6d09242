"""Reports cite the source documents by author, title and file (modelgen.model.sources)."""

import re
from pathlib import Path

from modelgen.model.sources import cite_sources, load_sources

SEEDS = Path(__file__).resolve().parents[3] / "shared" / "seeds"


def test_a_seed_mention_with_its_file_becomes_one_full_citation():
    text = "compared with seed 000 (000_f252785ea48c534d.txt), table of nonzero entries"
    cited = cite_sources(text)
    assert "Yuan Xin and Yu Zaixin, *Low-cost Doppler-aided strapdown inertial navigation system*" in cited
    assert cited.count("000_f252785ea48c534d.txt") == 1
    assert "seed 000" not in cited and cited.endswith(", table of nonzero entries")


def test_every_mention_is_cited_and_unknown_seeds_are_left_as_written():
    cited = cite_sources("seed 003's theorem; seed 001 strapdown; seed 999 unknown")
    assert "Zou Shikai" in cited and "Ke Yan" in cited
    assert "seed 999 unknown" in cited


def test_each_source_names_a_seed_file_and_the_files_present_are_all_listed():
    sources = load_sources()
    assert sorted(sources) == ["000", "001", "002", "003"]
    for key, source in sources.items():
        assert re.fullmatch(rf"{key}_[0-9a-f]{{16}}\.txt", source.file)
    if SEEDS.is_dir():  # the development tree keeps the documents beside the repository
        assert sorted(p.name for p in SEEDS.glob("*.txt")) == sorted(s.file for s in sources.values())
