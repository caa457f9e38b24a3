"""English wording of scene labels and descriptions (the scene layer's language helpers).

- :func:`label_text`: a label as written in text (``"coffee_table"`` → ``"coffee table"``).
- :func:`plural`: proper English plural of a label (``box`` → ``boxes``, ``shelf`` →
  ``shelves``, ``person`` → ``people``, ``coffee table`` → ``coffee tables``, ``pair of
  shoes`` → ``pairs of shoes``); labels that are already plural or plural-only (``stairs``,
  ``scissors``, ``books``) are returned unchanged.
- :func:`indefinite_article` / :func:`with_articles`: "a" or "an" by the first sound.
- :func:`strip_article`: a description without its leading article (``"a round white lace
  doily"`` → ``"round white lace doily"``), so questions that say "the …" never print "the a".

Question wording built on these (object phrases, counts, image markers) lives in
:mod:`spacedg.plugins.questions.language`.
"""

from __future__ import annotations

import re

__all__ = ["label_text", "plural", "indefinite_article", "with_articles", "strip_article"]

_LEADING_ARTICLE = re.compile(r"^\s*(?:a|an|the)\s+(?=\S)", re.IGNORECASE)


def strip_article(description: str) -> str:
    """``description`` without one leading "a", "an" or "the" (any case), whitespace trimmed.

    Only a whole word followed by more text is removed: ``"A-frame ladder"`` and ``"the"``
    stay as they are. Applied once, when an :class:`~spacedg.scene.model.Instance` is made.
    """
    text = str(description).strip()
    stripped = _LEADING_ARTICLE.sub("", text, count=1)
    return stripped if stripped else text

# Irregular singular → plural (lower case).
_IRREGULAR: dict[str, str] = {
    "person": "people",
    "man": "men",
    "woman": "women",
    "child": "children",
    "foot": "feet",
    "tooth": "teeth",
    "goose": "geese",
    "mouse": "mice",
    "ox": "oxen",
    "quiz": "quizzes",
    "cactus": "cacti",
    "fungus": "fungi",
    "die": "dice",
    "axis": "axes",
    "basis": "bases",
    "crisis": "crises",
    "analysis": "analyses",
    "thesis": "theses",
    "ellipsis": "ellipses",
    "index": "indices",
    "matrix": "matrices",
    "vertex": "vertices",
    "appendix": "appendices",
    "criterion": "criteria",
    "phenomenon": "phenomena",
    "medium": "media",
    "datum": "data",
    "bacterium": "bacteria",
    "curriculum": "curricula",
    "stimulus": "stimuli",
    # -f / -fe → -ves (the others take -s: roofs, chiefs, cliffs, safes)
    "shelf": "shelves",
    "bookshelf": "bookshelves",
    "knife": "knives",
    "leaf": "leaves",
    "half": "halves",
    "loaf": "loaves",
    "wolf": "wolves",
    "calf": "calves",
    "scarf": "scarves",
    "wife": "wives",
    "life": "lives",
    "thief": "thieves",
    "elf": "elves",
    "self": "selves",
    "sheaf": "sheaves",
    "hoof": "hooves",
    "wharf": "wharves",
    # -o → -oes
    "potato": "potatoes",
    "tomato": "tomatoes",
    "hero": "heroes",
    "echo": "echoes",
    "torpedo": "torpedoes",
    "veto": "vetoes",
    "volcano": "volcanoes",
    "mosquito": "mosquitoes",
    "domino": "dominoes",
    # -ch pronounced /k/ → -s
    "stomach": "stomachs",
    "monarch": "monarchs",
    "epoch": "epochs",
    "patriarch": "patriarchs",
}

# Same in singular and plural, or used only in the plural: returned unchanged.
_INVARIANT: frozenset[str] = frozenset(
    {
        "sheep", "fish", "deer", "moose", "series", "species", "aircraft", "spacecraft", "furniture",
        "equipment", "luggage", "baggage", "clothing", "laundry", "software", "hardware", "information",
        "scissors", "glasses", "eyeglasses", "sunglasses", "binoculars", "pliers", "tongs", "tweezers",
        "trousers", "pants", "jeans", "shorts", "pajamas", "pyjamas", "clothes", "headphones", "earphones",
        "earbuds", "stairs", "blinds", "curtains", "drapes", "goggles", "news", "chassis", "means",
    }
)

# Singular nouns that end in a single "s" (not "ss", "us", "is"): they take "-es".
_SINGULAR_S: frozenset[str] = frozenset({"lens", "gas", "canvas", "atlas", "bias", "alias", "iris", "chaos", "bus", "plus"})

# Irregular words that keep their plural at the end of a compound ("salesperson").
_COMPOUND_HEADS: tuple[str, ...] = (
    "person", "woman", "child", "tooth", "mouse", "goose", "shelf", "knife", "leaf", "loaf", "wife", "hero",
)

_SIBILANT = re.compile(r"(s|x|z|ch|sh)$")


#: label → :func:`label_text` (labels recur in every question of a scene; bounded).
_LABEL_TEXT: dict[str, str] = {}


def label_text(label: str) -> str:
    """A label as written in a question: underscores to spaces, whitespace collapsed, trimmed."""
    if type(label) is not str:
        return " ".join(str(label).replace("_", " ").split())
    text = _LABEL_TEXT.get(label)
    if text is None:
        if len(_LABEL_TEXT) >= 65_536:
            _LABEL_TEXT.clear()
        text = _LABEL_TEXT[label] = " ".join(label.replace("_", " ").split())
    return text


def _plural_word(word: str) -> str:
    if not word:
        return word
    if len(word) > 1 and word.isupper():  # acronyms: TV → TVs, PC → PCs
        return word + "s"
    lower = word.lower()
    if lower in _INVARIANT:
        return word
    if lower in _IRREGULAR:
        out = _IRREGULAR[lower]
    else:
        for singular in _COMPOUND_HEADS:
            # compounds ending in an irregular word: "bookshelf", "salesperson", "penknife"
            if lower.endswith(singular) and lower != singular:
                out = lower[: -len(singular)] + _IRREGULAR[singular]
                break
        else:
            out = _regular_plural(lower)
    return _match_case(word, out)


def _regular_plural(lower: str) -> str:
    if lower.endswith("s") and not lower.endswith(("ss", "us", "is")) and lower not in _SINGULAR_S:
        return lower  # already plural ("books", "papers")
    if _SIBILANT.search(lower):
        return lower + "es"  # box → boxes, glass → glasses, bench → benches, bus → buses
    if lower.endswith("y") and len(lower) > 1 and lower[-2] not in "aeiou":
        return lower[:-1] + "ies"  # battery → batteries (but toy → toys)
    return lower + "s"


def _match_case(original: str, plural_form: str) -> str:
    if original.islower():
        return plural_form
    if original[0].isupper() and original[1:].islower():
        return plural_form[0].upper() + plural_form[1:]
    # mixed case ("iPad"): keep the original and add the suffix it would get in lower case
    lower = original.lower()
    if plural_form.startswith(lower):
        return original + plural_form[len(lower):]
    return plural_form


def plural(label: str) -> str:
    """English plural of a (possibly multi-word) label.

    The head noun is pluralised: the last word, or the word before ``" of "`` (``"bottle of
    water"`` → ``"bottles of water"``). Underscores are read as spaces.
    """
    text = label_text(label)
    if not text:
        return text
    head, sep, tail = text.partition(" of ")
    words = head.split(" ")
    words[-1] = _plural_word(words[-1])
    return " ".join(words) + (sep + tail if sep else "")


# Letters whose spoken name starts with a vowel sound (acronyms: "an HDMI cable", "a TV").
_VOWEL_SOUND_LETTERS = frozenset("AEFHILMNORSX")
# Vowel-letter words spoken with a consonant sound, and silent-h words.
_A_PREFIXES = ("uni", "use", "usb", "uten", "eu", "one", "once", "ewe")
_AN_PREFIXES = ("hour", "honest", "honor", "honour", "heir")


def indefinite_article(label: str) -> str:
    """``"a"`` or ``"an"`` for ``label`` by its first sound (simple spelling rules, acronyms by letter name)."""
    text = label_text(label)
    if not text:
        return "a"
    word = text.split(" ")[0]
    if len(word) > 1 and word.isupper():
        return "an" if word[0] in _VOWEL_SOUND_LETTERS else "a"
    lower = word.lower()
    if lower.startswith(_AN_PREFIXES):
        return "an"
    if lower.startswith(_A_PREFIXES):
        return "a"
    return "an" if lower[0] in "aeiou" else "a"


_A_BEFORE = re.compile(r"\b([Aa]) (\w[\w-]*)")


def with_articles(text: str) -> str:
    """``text`` with each article "a" corrected to "an" before a vowel sound (``"a orange cup"`` →
    ``"an orange cup"``); other words are untouched."""
    def fix(match: re.Match[str]) -> str:
        article = indefinite_article(match.group(2))
        if match.group(1) == "A":
            article = article.capitalize()
        return f"{article} {match.group(2)}"

    return _A_BEFORE.sub(fix, text)
