"""The label lexicon (spacedg.scene.lexicon): relations, extension by JSON, typical sizes."""

from __future__ import annotations

import json

import pytest

from spacedg.errors import FileFormatError
from spacedg.scene.lexicon import BUILTIN, LEXICON_ENV, Lexicon, default_lexicon, load_lexicon


@pytest.mark.parametrize(
    ("a", "b"),
    [
        ("chair", "armchair"), ("armchair", "chair"), ("monitor", "tv"), ("TV", "television"), ("table", "desk"),
        ("table", "coffee_table"), ("stool", "chair"), ("lamp", "floor lamp"), ("sofa", "couch"), ("plant", "small plant"),
        ("trash can", "wastebasket"), ("office chair", "chair"),
    ],
)
def test_related_labels(a: str, b: str) -> None:
    assert BUILTIN.related(a, b) and BUILTIN.related(b, a)


@pytest.mark.parametrize(("a", "b"), [("chair", "table"), ("chair", "Chair"), ("cup", "monitor"), ("sofa", "chair"), ("book", "bookshelf"),
                                   ("office chair", "armchair")])  # siblings under "chair" are not taken for one another
def test_unrelated_labels(a: str, b: str) -> None:
    assert not BUILTIN.related(a, b)


def test_kinds_are_transitive_and_shows_books() -> None:
    assert {"chair", "seat"} <= BUILTIN.broader("armchair")
    assert BUILTIN.shown_by("book") >= {"bookshelf", "shelf"}
    assert BUILTIN.confuses("book", "bookcase")  # a synonym of bookshelf shows books too
    assert not BUILTIN.confuses("bookshelf", "book")  # a book does not make "bookshelf" ambiguous
    assert BUILTIN.typical_size("couch") == BUILTIN.typical_size("sofa") and BUILTIN.typical_size("unicorn") is None


def test_extension_by_json_and_environment(tmp_path, monkeypatch: pytest.MonkeyPatch) -> None:
    extra = tmp_path / "lexicon.json"
    extra.write_text(json.dumps({
        "kinds": {"Ottoman": ["footstool"]}, "related": [["ottoman", "pouf"]], "shows": {"kitchen counter": ["bottle"]},
        "synonyms": [["footstool", "foot rest"]], "sizes": {"ottoman": [0.6, 0.45]},
    }))
    lex = load_lexicon(extra)
    assert lex.related("ottoman", "foot rest") and lex.related("pouf", "ottoman") and lex.confuses("bottle", "kitchen counter")
    assert lex.typical_size("Ottoman") == (0.6, 0.45) and lex.related("chair", "armchair")  # the built-ins stay
    assert lex.digest() != BUILTIN.digest() and Lexicon.from_dict(lex.to_dict()).digest() == lex.digest()
    monkeypatch.setenv(LEXICON_ENV, str(extra))
    assert default_lexicon().related("ottoman", "pouf")
    monkeypatch.delenv(LEXICON_ENV)
    assert not default_lexicon().related("ottoman", "pouf")


@pytest.mark.parametrize(
    ("data", "message"),
    [
        ({"kinds": ["chair"]}, "'kinds' must map"), ({"related": [["a", "b", "c"]]}, "is a pair"), ({"colours": {}}, "unknown key"),
        ({"sizes": {"chair": [1.0]}}, "longest side"), ({"synonyms": [["tv", ""]]}, "non-empty label"),
    ],
)
def test_bad_lexicon_files_name_the_problem(tmp_path, data: dict, message: str) -> None:
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(FileFormatError, match=message):
        load_lexicon(path)
