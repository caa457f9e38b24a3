"""Reading a model's answer out of its text: one parser per SpaceDG answer type.

Every parser first takes the content of the first ``<answer>…</answer>`` (:func:`extract_answer_text`)
and returns ``None`` when it cannot find one unambiguous answer. Conventions (letters inside words,
"the answer is X", the last number wins, "1,234", number words, units converted to metres) are
stated on each function; :mod:`spacedg.eval.scoring` turns the parsed values into scores.
"""

from __future__ import annotations

import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from decimal import Decimal
from typing import Any

from spacedg.plugins.answers import MCQ_LETTERS

__all__ = ["extract_answer_text", "parse_mcq", "parse_number", "parse_yes_no", "parse_count", "parse_size_list"]

# ------------------------------------------------------------------ extraction
_ANSWER_TAG = re.compile(r"<\s*answer\b[^>]*>(.*?)</\s*answer\s*>", re.IGNORECASE | re.DOTALL)


def extract_answer_text(prediction: str | None) -> str:
    """The stripped content of the first ``<answer>…</answer>``, else the whole text stripped.

    Tags are matched case-insensitively and non-greedily (the first closing tag ends the
    first answer), with the public evaluator's tolerance (``< answer >``, ``<answer id=1>``,
    ``</ answer >``); the content may span lines. ``None`` gives ``""``; other non-strings are
    converted with ``str``.
    """
    if prediction is None:
        return ""
    text = prediction if isinstance(prediction, str) else str(prediction)
    match = _ANSWER_TAG.search(text)
    return (match.group(1) if match else text).strip()


# ------------------------------------------------------------------ MCQ
# (a) the whole answer is one option token: "B", "(b)", "**C**", "D.", "Option B", "'A'".
_WHOLE_LETTER = re.compile(
    r"^[\s(\[{*\"'`]*(?:(?:option|choice)\s*)?[(\[]?\s*([A-Da-d])\s*[)\]}]?[\s.)\]}*\"'`:,;!]*$",
    re.IGNORECASE,
)
# (b) explicit statements: "the answer is B", "Answer: (C)", "final answer - d", "correct option is A".
_EXPLICIT = re.compile(
    r"\b(?:answer|(?:correct|right|best)\s+(?:option|choice))\b\s*"
    r"(?:is|would\s+be|should\s+be|will\s+be|=|:|-|–|—)?\s*"
    r"(?:\b(?:option|choice|letter)\b\s*)?[(\[*\"'`]*\s*([A-Da-d])(?![A-Za-z0-9'])",
    re.IGNORECASE,
)
# (c) the answer starts with an option label: "B. right", "(B) right", "B) right", "B: right".
_LEADING = re.compile(r"^[\s*\"'`]*(?:\(([A-Da-d])\)|([A-Da-d])\s*[.):])(?:\s|$)")
# any single letter A–D standing alone (not part of a word, number, or "3D").
_LONE = re.compile(r"(?<![A-Za-z0-9'’_])([A-Da-d])(?![A-Za-z0-9'’_])")
_VERBS_AFTER_OPTION = frozenset({"is", "seems", "would", "should", "fits", "matches", "looks", "best", "appears", "describes",
                                 # an article is never followed by a conjunction: "A or B" names two options
                                 "or", "and", "nor", "vs", "versus"})
_PUNCT = re.compile(r"[^\w\s]+")


def _is_option_token(text: str, start: int, end: int) -> bool:
    """Whether the single letter ``text[start:end]`` reads as an option, not an English word.

    ``b``, ``c``, ``d`` always do (in either case). ``A``/``a`` is rejected when it reads as
    the article: followed by whitespace and a word (unless the word is a verb such as "is":
    "A is correct"), and not wrapped in brackets / quotes / asterisks. A letter followed by
    ``.`` then a letter (``a.m.``) is rejected.
    """
    letter = text[start:end]
    after = text[end:]
    before = text[:start]
    if re.match(r"[.]\w", after):
        return False
    if letter not in "Aa":
        return True
    if re.search(r"[(\[{*\"'`<>]\s*$", before) and re.match(r"\s*[)\]}*\"'`<>]", after):
        return True
    word = re.match(r"\s+([A-Za-z]+)", after)
    if word is None:
        return True  # end of text, punctuation ("a." / "A)"), a digit…
    return word.group(1).lower() in _VERBS_AFTER_OPTION


def _normalise_option_text(text: str) -> str:
    return " ".join(_PUNCT.sub(" ", text.lower()).split())


def _option_texts(options: Sequence[str] | Mapping[str, Any] | None) -> dict[str, str]:
    """Letter → option text from ``["A. text", …]`` or ``{"A": "text", …}``."""
    if not options:
        return {}
    out: dict[str, str] = {}
    if isinstance(options, Mapping):
        for key, value in options.items():
            letter = str(key).strip().upper()
            if letter in MCQ_LETTERS and value is not None and str(value).strip():
                out[letter] = str(value)
        return out
    for i, line in enumerate(options):
        if not isinstance(line, str):
            continue
        m = re.match(r"^\s*\(?([A-Da-d])[.):]\s*(.*)$", line, re.DOTALL)
        if m:
            out[m.group(1).upper()] = m.group(2)
        elif i < 4:
            out[MCQ_LETTERS[i]] = line
    return out


def parse_mcq(text: str | None, options: Sequence[str] | Mapping[str, Any] | None = None) -> str | None:
    """One option letter ``"A"``–``"D"`` (upper case) from a prediction, or ``None``.

    Runs on :func:`extract_answer_text` of ``text``. Precedence (first rule that decides):

    a. the whole answer is one option token: ``"B"``, ``"c"``, ``"(b)"``, ``"**D**"``,
       ``"A."``, ``"Option C"`` (here a lone lower-case ``a`` counts);
    b. explicit statements ``answer is X`` / ``answer: X`` / ``final answer - X`` /
       ``correct option is X``: if they name one letter it wins; if they name two different
       letters the prediction is ambiguous → ``None``; a lower-case ``a`` followed by a word
       is the article, not an option (``"the answer is a chair"``);
    c. the answer starts with an option label ``"B. right"``, ``"(B) right"``, ``"B) …"``;
    d. the answer ends with a standalone letter (``"… so B."``), unless that letter closes a
       list of letters (``"A, B, C or D"``);
    e. exactly one distinct standalone letter anywhere (``"I pick C because …"``); several
       distinct letters (``"A/B/C/D"``) → ``None``;
    f. no letter at all, ``options`` given, and the normalised answer equals exactly one
       option's text (``"left"`` for ``"B. left"``) → that option's letter.

    Letters inside words never count (the ``A`` of ``Answer``), nor ``D`` in ``3D``; the
    article ``a``/``A`` followed by a word never counts (see rules above), except a verb
    (``"A is correct"``) or a conjunction (``"A or B"`` names two options: ambiguous → ``None``).
    """
    answer = extract_answer_text(text)
    if not answer:
        return None
    m = _WHOLE_LETTER.match(answer)
    if m:
        return m.group(1).upper()
    explicit = set()
    for m in _EXPLICIT.finditer(answer):
        letter = m.group(1)
        if letter == "a" and not _is_option_token(answer, m.start(1), m.end(1)):
            continue
        explicit.add(letter.upper())
    if len(explicit) == 1:
        return explicit.pop()
    if len(explicit) > 1:
        return None
    m = _LEADING.match(answer)
    if m:
        return (m.group(1) or m.group(2)).upper()
    lone = [m for m in _LONE.finditer(answer) if _is_option_token(answer, m.start(1), m.end(1))]
    if lone:
        last = lone[-1]
        at_end = not answer[last.end(1):].strip(" \t\r\n.!)]}*\"'`>")
        in_list = re.search(r"[A-Da-d][\s)\]]*(?:,|/|\bor\b|\band\b)[\s(\[]*$", answer[:last.start(1)])
        if at_end and not in_list:
            return last.group(1).upper()
        letters = {m.group(1).upper() for m in lone}
        return letters.pop() if len(letters) == 1 else None
    texts = {letter: _normalise_option_text(t) for letter, t in _option_texts(options).items()}
    target = _normalise_option_text(answer)
    hits = [letter for letter, t in texts.items() if t and t == target]
    return hits[0] if len(hits) == 1 else None


# ------------------------------------------------------------------ yes / no
_YES_NO = re.compile(r"\b(yes|no)\b", re.IGNORECASE)
# a final-answer statement: "the answer is yes", "Answer: no", "final answer - yes", "so no", "therefore, yes"
_YN_STATEMENT = re.compile(
    r"(?:\banswer\b\s*(?:is|would\s+be|should\s+be|will\s+be|=|:|-|–|—)?|"
    r"\b(?:so|therefore|thus|hence|overall|in\s+conclusion)\b\s*[,:]?)"
    r"\s*[*\"'`(\[]*\s*(yes|no)\b",
    re.IGNORECASE,
)
# a hedge: the two words offered as alternatives ("yes or no", "yes/no", "yes and no", "maybe yes, maybe no",
# "yes, but also no", "either yes or no"), the second one closing the phrase
_YN_HEDGE = re.compile(
    r"\b(yes|no)\b[\s*\"'`.,;:!)\]]*(?:/|\\|\bor\b|\band\b|\bbut\s+(?:also|maybe|perhaps|possibly)\b|"
    r"\b(?:maybe|perhaps|possibly)\b|\bor\s+(?:maybe|perhaps|possibly)\b)[\s*\"'`,]*\b(yes|no)\b"
    r"(?!\s+[A-Za-z])",  # "Yes, and no other lamp" is an answer, not a hedge: the second word ends the phrase
    re.IGNORECASE,
)
_LINE_START = re.compile(r"^[\W_]*(yes|no)\b", re.IGNORECASE)
_LINE_END = re.compile(r"\b(yes|no)[\W_]*$", re.IGNORECASE)


def _hedged_at(text: str, word: re.Match[str]) -> bool:
    """Whether the deciding yes/no ``word`` (group 1 of a match in ``text``) opens or closes a hedge."""
    return any(
        h.group(1).lower() != h.group(2).lower() and word.start(1) in (h.start(1), h.start(2))
        for h in _YN_HEDGE.finditer(text)
    )


def parse_yes_no(text: str | None) -> str | None:
    """``"yes"`` or ``"no"``: the answer's one yes/no word, or its final answer; else ``None``.

    Runs on :func:`extract_answer_text` (so ``<answer>…</answer>`` wins over text around it).
    Whole words only (``"not"``, ``"none"``, ``"nobody"`` do not count), any case.

    1. Only one of the two words occurs → that word (``"No, there is none."`` → no).
    2. Both occur: the **final answer** decides, in this order:

       a. the last final-answer statement: ``answer is X`` / ``answer: X`` / ``final answer X`` /
          ``so X`` / ``therefore X`` / ``thus X`` / ``hence X`` (``"At first I'd say no, but
          the answer is yes"`` → yes);
       b. else the last non-empty line, when it ends with one of the words (``"No, wait —
          yes."`` → yes) or else starts with one (``"…\nYes, there is no other lamp."`` →
          yes).

       The deciding word must not be part of a **hedge**, the two words offered as
       alternatives: ``"yes or no"``, ``"yes/no"``, ``"yes and no"``, ``"maybe yes, maybe
       no"``, ``"Yes, but also no"``, ``"the answer is yes or no"`` → ``None`` (a hedge
       elsewhere, e.g. the question restated before a final ``"Yes."``, does not matter).
       No statement and a last line that neither ends nor starts with an answer word →
       ambiguous → ``None``.
    """
    answer = extract_answer_text(text)
    words = {m.group(1).lower() for m in _YES_NO.finditer(answer)}
    if len(words) < 2:
        return words.pop() if words else None
    statements = list(_YN_STATEMENT.finditer(answer))
    if statements:
        last = statements[-1]
        return None if _hedged_at(answer, last) else last.group(1).lower()
    last_line = [line.strip() for line in answer.splitlines() if line.strip()][-1]
    m = _LINE_END.search(last_line) or _LINE_START.match(last_line)
    if m is None or _hedged_at(last_line, m):
        return None
    return m.group(1).lower()


# ------------------------------------------------------------------ numbers
_UNITS: dict[str, Decimal] = {
    "mm": Decimal("0.001"), "millimeter": Decimal("0.001"), "millimetre": Decimal("0.001"),
    "cm": Decimal("0.01"), "centimeter": Decimal("0.01"), "centimetre": Decimal("0.01"),
    "m": Decimal(1), "meter": Decimal(1), "metre": Decimal(1),
    "km": Decimal(1000), "kilometer": Decimal(1000), "kilometre": Decimal(1000),
    "ft": Decimal("0.3048"), "foot": Decimal("0.3048"), "feet": Decimal("0.3048"),
    "inch": Decimal("0.0254"), "inches": Decimal("0.0254"),
}
_UNIT_RE = (
    r"(?P<unit>mm|cm|km|m|ft|feet|foot|inch(?:es)?|"
    r"(?:milli|centi|kilo)?met(?:er|re)s?|met(?:er|re)s?)(?![A-Za-z])"
)
_NUMBER_CORE = r"(?:\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?"
_NUMBER_THOUSANDS = r"(?:\d{1,3}(?:,\d{3})+(?![\d])(?!,\d)(?:\.\d+)?|\d+(?:\.\d+)?|\.\d+)(?:[eE][-+]?\d+)?"
_WHOLE_DECIMAL_COMMA = re.compile(rf"^\s*(?P<sign>[-+−])?(?P<int>\d+),(?P<frac>\d+)\s*(?:{_UNIT_RE})?\s*$")


@dataclass(frozen=True)
class _Num:
    start: int
    end: int
    value: Decimal
    unit: str | None


def _unit_factor(unit: str | None) -> Decimal:
    if unit is None:
        return Decimal(1)
    key = unit.lower()
    if key in _UNITS:
        return _UNITS[key]
    key = key.rstrip("s") if key.endswith(("ers", "res")) else key
    return _UNITS.get(key, Decimal(1))


def _digit_numbers(text: str, thousands: bool) -> list[_Num]:
    """Every number written with digits, left to right, with the unit written right after it.

    A number (or its sign) must not directly follow a letter other than ``x``, a digit, ``_``
    or ``.``: ``"view2"`` and the ``.3`` of ``"1.2.3"`` are not read, ``"0.5x1.2x2"`` gives
    three numbers, and in ``"3-4"`` the dash is a range (3 and 4, not −4).
    With ``thousands``, ``d{1,3}(,ddd)+`` is one number (``"1,234"`` → 1234); otherwise a
    comma always separates numbers. Numbers directly followed by ``D``/``d`` as a word
    (``"3D"``, ``"2D"``) are skipped, and so are uncertainties after ``±`` / ``+/-``.
    """
    core = _NUMBER_THOUSANDS if thousands else _NUMBER_CORE
    pattern = re.compile(
        rf"(?<![A-WYZa-wyz0-9_.])(?P<sign>[-+−](?=[\d.]))?(?P<num>{core})(?P<tail>\s*{_UNIT_RE})?"
    )
    out: list[_Num] = []
    for m in pattern.finditer(text):
        num = m.group("num")
        after = text[m.end("num"):]
        if re.match(r"[dD](?![A-Za-z])", after) or re.search(r"(?:±|\+/-|\+-)\s*$", text[: m.start()]):
            continue
        value = Decimal(num.replace(",", ""))
        if m.group("sign") in ("-", "−"):
            value = -value
        unit = m.group("unit")
        out.append(_Num(m.start(), m.end(), value, unit))
    return out


_UNITS_WORDS = {
    "zero": 0, "one": 1, "two": 2, "three": 3, "four": 4, "five": 5, "six": 6, "seven": 7,
    "eight": 8, "nine": 9,
}
_TEENS = {
    "ten": 10, "eleven": 11, "twelve": 12, "thirteen": 13, "fourteen": 14, "fifteen": 15,
    "sixteen": 16, "seventeen": 17, "eighteen": 18, "nineteen": 19,
}
_TENS = {
    "twenty": 20, "thirty": 30, "forty": 40, "fifty": 50, "sixty": 60, "seventy": 70,
    "eighty": 80, "ninety": 90,
}
_SCALES = {"hundred": 100, "thousand": 1000, "million": 1_000_000}
_WORD = re.compile(r"[A-Za-z]+")


def _word_class(word: str) -> str | None:
    if word == "zero":
        return "zero"
    if word in _UNITS_WORDS:
        return "unit"
    if word in _TEENS:
        return "teen"
    if word in _TENS:
        return "tens"
    if word in _SCALES:
        return "scale"
    if word == "dozen":
        return "dozen"
    return None


# which word class may follow which inside one number ("twenty one", "one hundred and five")
_FOLLOWS = {
    None: {"zero", "unit", "teen", "tens", "a"},
    "a": {"scale", "dozen"},
    "unit": {"scale", "dozen"},
    "teen": {"scale"},
    "tens": {"unit", "scale"},
    "scale": {"unit", "teen", "tens", "scale", "and"},
    "and": {"unit", "teen", "tens"},
    "dozen": set(),
    "zero": set(),
}


def _word_value(words: list[str]) -> int:
    total, current = 0, 0
    for w in words:
        if w in ("a", "and"):
            continue
        if w in _UNITS_WORDS:
            current += _UNITS_WORDS[w]
        elif w in _TEENS:
            current += _TEENS[w]
        elif w in _TENS:
            current += _TENS[w]
        elif w == "dozen":
            current = max(current, 1) * 12
        elif w == "hundred":
            current = max(current, 1) * 100
        else:  # thousand, million
            total += max(current, 1) * _SCALES[w]
            current = 0
    return total + current


def _word_numbers(text: str) -> list[_Num]:
    """Numbers written in English words, left to right (integers; no units).

    Reads zero–nineteen, the tens, ``hundred``/``thousand``/``million``, ``dozen`` (12), an
    ``and`` after a scale word and ``a`` before a scale word or ``dozen`` (``"a dozen"`` →
    12, ``"one hundred and five"`` → 105), joined by spaces or hyphens (``"twenty-one"``,
    ``"twenty one"``). Words that cannot continue a number start a new one (``"one two"`` →
    1 and 2). A bare ``a``/``and`` is not a number. ``"point"`` decimals and ordinals are
    not read.
    """
    tokens = [(m.start(), m.end(), m.group(0).lower()) for m in _WORD.finditer(text)]
    out: list[_Num] = []
    run: list[tuple[int, int, str]] = []
    prev: str | None = None

    def close() -> None:
        nonlocal run, prev
        while run and run[-1][2] in ("a", "and"):
            run.pop()
        if run:
            out.append(_Num(run[0][0], run[-1][1], Decimal(_word_value([w for _, _, w in run])), None))
        run, prev = [], None

    for i, (start, end, word) in enumerate(tokens):
        cls = "a" if word == "a" else "and" if word == "and" else _word_class(word)
        joined = bool(run) and re.fullmatch(r"[\s-]+", text[run[-1][1]:start]) is not None
        if run and (not joined or cls not in _FOLLOWS[prev]):
            close()
        if cls is None or (not run and cls == "and"):
            continue
        if cls not in _FOLLOWS[prev]:
            continue
        if cls == "a":
            nxt = tokens[i + 1][2] if i + 1 < len(tokens) else ""
            if _word_class(nxt) not in ("scale", "dozen"):
                continue
        run.append((start, end, word))
        prev = cls
    close()
    return out


def _to_float(value: Decimal) -> float:
    return float(value)


def _numbers(text: str, *, thousands: bool, convert_units: bool) -> list[float]:
    """Digit numbers (with units applied); if none, number words. Left to right."""
    found = _digit_numbers(text, thousands)
    if not found:
        found = _word_numbers(text)
    values = []
    for num in found:
        value = num.value * _unit_factor(num.unit) if convert_units else num.value
        values.append(_to_float(value))
    return values


def parse_number(text: str | None, *, convert_units: bool = True) -> float | None:
    """One number from a prediction: the **last** number of the answer, or ``None``.

    Conventions (all applied to :func:`extract_answer_text` of ``text``, so a tagged answer
    wins over reasoning around it):

    * Digits take precedence over number words: words (``"twenty-one"``, ``"one hundred and
      five"``, ``"a dozen"``, ``"zero"``) are read only when the answer has no digits.
    * ``"1,234"`` (groups of exactly three digits after the comma) is 1234. Any other comma
      separates numbers (``"1,2,3"`` → 3), except that an answer consisting of one number
      with a decimal comma (``"1,5"``, ``"2,75 m"``) is read as 1.5 / 2.75.
    * Decimals (``"0.5"``, ``".5"``), a sign (``"-2"``, ``"−2"``), scientific notation
      (``"1e-3"``, ``"2.5E2"``); a dash directly after a digit is a range (``"3-4"`` → 4).
    * With ``convert_units`` a length unit written right after the number converts to metres:
      mm, cm, m, km, ft / foot / feet, inch(es), and the spelled metric names (``"30cm"`` →
      0.3, ``"5 ft"`` → 1.524). Other words after a number are ignored.
    * ``"3D"``/``"2D"`` are not numbers; digits glued to letters (``"view2"``) are not read;
      an uncertainty after ``±`` / ``+/-`` is skipped (``"3.2 m ± 0.5"`` → 3.2).

    Returns a finite float; ``None`` when there is no number or it overflows.
    """
    answer = extract_answer_text(text)
    if not answer:
        return None
    m = _WHOLE_DECIMAL_COMMA.match(answer)
    if m and len(m.group("frac")) != 3:
        value = Decimal(f"{m.group('int')}.{m.group('frac')}")
        if m.group("sign") in ("-", "−"):
            value = -value
        if convert_units:
            value *= _unit_factor(m.group("unit"))
        return _finite(_to_float(value))
    values = _numbers(answer, thousands=True, convert_units=convert_units)
    return _finite(values[-1]) if values else None


def _finite(value: float) -> float | None:
    return value if math.isfinite(value) else None


def parse_count(text: str | None) -> int | None:
    """A non-negative integer count, or ``None``.

    The number is read as by :func:`parse_number` without unit conversion (last number,
    digits before words, ``"1,234"`` → 1234). It must be a whole number ≥ 0: ``"3"``,
    ``"3.0"``, ``"three"``, ``"twenty one chairs"`` → 3, 3, 3, 21; ``"2.5"`` and ``"-1"``
    → ``None``.
    """
    value = parse_number(text, convert_units=False)
    if value is None or value < 0 or value != int(value):
        return None
    return int(value)


_BRACKET_GROUP = re.compile(r"[\[(]([^\[\]()]*)[\])]")
# an enumeration label of a numbered list ("1. ", "2) ", "3: ", "(1) "), at a line start or after a separator
_ENUM_LABEL = re.compile(r"(?:^|(?<=[\s,;]))(?:\((?P<p>\d{1,2})\)|(?P<n>\d{1,2})[.):])(?=[ \t]+\S)", re.MULTILINE)
# what may stand between two numbers of one written list: separators, "and", "by", nothing else
_LIST_GAP = re.compile(r"^[\s,;/*x×]*(?:(?:and|by)[\s,;/*x×]*)?$", re.IGNORECASE)


def _strip_enumeration(text: str) -> str:
    """``text`` with the labels of a numbered list blanked out (same length, so offsets hold).

    Labels count only when they number 1, 2, …, k (k ≥ 2) in order: all of them anywhere, or
    else those at line starts. ``"1. 0.31\n2. 0.9\n3. 1.11"`` → the three values; ``"I see
    2. The edges …"`` keeps its 2 (a lone label is not a list).
    """
    def numbered(labels: list[re.Match[str]]) -> bool:
        values = [int(m.group("p") or m.group("n")) for m in labels]
        return len(values) >= 2 and values == list(range(1, len(values) + 1))

    labels = list(_ENUM_LABEL.finditer(text))
    if not numbered(labels):
        labels = [m for m in labels if m.start() == 0 or text[m.start() - 1] == "\n"]
        if not numbered(labels):
            return text
    out = list(text)
    for m in labels:
        out[m.start():m.end()] = " " * (m.end() - m.start())
    return "".join(out)


def _last_triple(nums: list[_Num], text: str) -> list[_Num] | None:
    """The last run of exactly three numbers written as one list (only separators between them:
    spaces, ``,`` ``;`` ``/`` ``x`` ``×`` ``*``, ``and``, ``by``), or ``None``."""
    runs: list[list[_Num]] = []
    for num in nums:
        if runs and _LIST_GAP.match(text[runs[-1][-1].end:num.start]):
            runs[-1].append(num)
        else:
            runs.append([num])
    triples = [run for run in runs if len(run) == 3]
    return triples[-1] if triples else None


def parse_size_list(text: str | None, *, convert_units: bool = True) -> list[float] | None:
    """Three lengths in metres from a prediction, in the order written, or ``None``.

    Runs on :func:`extract_answer_text`. Commas always separate numbers here (box edges are
    never thousands of metres), and the labels of a numbered list are not values
    (``"1. 0.31\n2. 0.9\n3. 1.11"`` → ``[0.31, 0.9, 1.11]``; see :func:`_strip_enumeration`).
    Choice of the three numbers (a box has three edge lengths; the answer must name three):

    1. the last bracketed group ``[a, b, c]`` / ``(a, b, c)`` holding exactly 3 numbers;
    2. else, if the answer holds exactly 3 numbers, those (``"0.5 x 1.2 x 2 m"``,
       ``"shortest 0.4, middle 0.6 and longest 1.0"``);
    3. **extra numbers**: else the last run of exactly three numbers written as one list, with
       only separators between them (``", "``, ``" x "``, ``"and"``, ``"by"``): ``"The 3 edges
       are 0.31, 0.9 and 1.11 m"`` → the three edges, ``"0.31, 0.9, 1.11 (about 2 ft)"`` → the
       first three, a corrected ``"0.3, 0.8, 1.0, no: 0.31, 0.9, 1.11"`` → the last three;
    4. else ``None``: four or more values in one list (``"0.31, 0.9, 1.11, 2.0"``,
       ``"[0.31, 0.9, 1.11, 2.0]"``) do not say which three are the edges, and guessing the
       first or the last three would reward one arbitrary guess.

    Units (with ``convert_units``) as in :func:`parse_number`; a unit written only after the
    last of the three applies to all three (``"50 x 120 x 200 cm"``). Numbers in words are read
    only when the answer has no digits. Fewer than 3 numbers or a non-finite value → ``None``.
    """
    answer = extract_answer_text(text)
    if not answer:
        return None
    answer = _strip_enumeration(answer)
    chosen: list[_Num] | None = None
    for group in reversed(list(_BRACKET_GROUP.finditer(answer))):
        nums = _digit_numbers(group.group(1), thousands=False)
        if len(nums) == 3:
            chosen = nums
            tail = re.match(rf"\s*{_UNIT_RE}", answer[group.end():])
            if tail and all(n.unit is None for n in nums):
                chosen = [_Num(n.start, n.end, n.value, tail.group("unit")) for n in nums]
            break
    if chosen is None:
        nums = _digit_numbers(answer, thousands=False) or _word_numbers(answer)
        chosen = nums if len(nums) == 3 else _last_triple(nums, answer)
        if chosen is None:
            return None
        if chosen[-1].unit is not None and all(n.unit is None for n in chosen[:-1]):
            chosen = [_Num(n.start, n.end, n.value, chosen[-1].unit) for n in chosen]
    values = [_to_float(n.value * _unit_factor(n.unit)) if convert_units else _to_float(n.value) for n in chosen]
    if not all(math.isfinite(v) for v in values):
        return None
    return values
