"""Shared wording helpers for question families (English).

- :func:`count_phrase`: ``"1 chair"``, ``"3 chairs"``.
- :func:`object_phrase`: how a question names an object (its description, else its label).
- :func:`find_in_image`: ``"In image A, find the red cup."``.
- :func:`label_text`, :func:`plural`, :func:`indefinite_article`, :func:`with_articles`: the
  English morphology of labels, from :mod:`spacedg.scene.language` (re-exported here for family
  authors).

Option lettering and seeded option shuffles live in
:func:`~spacedg.plugins.questions.geometry.build_mcq`; how a question names a scene instance
(:func:`~spacedg.plugins.questions.records.phrase`) builds on :func:`object_phrase`.
"""

from __future__ import annotations

from spacedg.scene.language import indefinite_article, label_text, plural, with_articles

__all__ = ["label_text", "plural", "count_phrase", "indefinite_article", "with_articles", "object_phrase", "find_in_image", "IMAGE_NAMES"]

#: How questions name the images of a record, in ``QARecord.views`` order.
IMAGE_NAMES: tuple[str, ...] = ("A", "B", "C", "D")


def count_phrase(count: int, label: str) -> str:
    """``"1 chair"``, ``"0 chairs"``, ``"3 boxes"``."""
    return f"{count} {label_text(label) if count == 1 else plural(label)}"


def object_phrase(label: str, description: str = "") -> str:
    """How a question names an object: its view-invariant description, else its label.

    ``("chair", "black plastic chair")`` → ``"black plastic chair"``; ``("chair", "")`` →
    ``"chair"``. A description that does not mention the label gets it appended in
    parentheses (``"red hardcover (book)"``) so the category is always stated.
    """
    if type(label) is not str or type(description) is not str:
        return _object_phrase(label, description)
    key = (label, description)
    text = _PHRASES.get(key)
    if text is None:
        if len(_PHRASES) >= 65_536:
            _PHRASES.clear()
        text = _PHRASES[key] = _object_phrase(label, description)
    return text


#: (label, description) → :func:`object_phrase` (every candidate names its objects; bounded).
_PHRASES: dict[tuple[str, str], str] = {}


def _object_phrase(label: str, description: str) -> str:
    text = " ".join(str(description).split()).rstrip(".")
    name = label_text(label)
    if not text:
        return name
    if name.lower() not in text.lower():
        return f"{text} ({name})"
    return text


def find_in_image(phrase: str, image: int) -> str:
    """The marker sentence that tells where an object is seen: ``"In image A, find the red cup."``."""
    return f"In image {IMAGE_NAMES[image]}, find the {phrase}."
