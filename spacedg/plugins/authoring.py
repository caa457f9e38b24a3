"""The public helper API for question-family authors: everything a family needs, from one import.

::

    from spacedg.plugins.authoring import QuestionFamily, VisibilityIndex, build_mcq, make_record, hookimpl

A third-party family imports from here (and from :mod:`spacedg.plugins` / :mod:`spacedg.errors`),
never from the built-in family modules or their private helpers: the names below are the ones
the built-ins are written with, re-exported (not copied), so a family written against this
module generates records exactly as a built-in would, and keeps working while the built-ins'
own layout changes. A complete example package (entry point, family, tests) is
``tests/plugins/spacedg-nearest-object``; docs/plugins.md ("Writing a plugin") walks through it.
Degradation authors need only :mod:`spacedg.plugins` (``DegradationSpec``, ``ParamSpec``, …).

Conventions (every name below follows them): world coordinates in **metres**; cameras are
OpenCV (x right, y down, z forward), ``Camera.cam_to_world`` is a 4×4 camera → world pose;
"up" is ``Scene.up`` (a unit vector against gravity, never a fixed world axis); an object's
centre is its oriented box's centre and its size the box ``extents`` (full side lengths);
angles are in degrees unless a name says radians; every random choice is drawn from the
``numpy.random.Generator`` that ``generate(scene, rng)`` receives (seeded per scene and family
by the question index), never from global state.

Declaring and registering a family
    - :func:`hookimpl`: decorator of the hook ``spacedg_register_question_families(register)``; call ``register(family)`` once per family.
    - :class:`QuestionFamily`: the declaration: name (= ``question_type``), task group, answer types, sub types, ``num_views``, ``needs``, ``generate(scene, rng)``.
    - :data:`SCENE_NEEDS`: what ``needs`` may name: ``visibility``, ``covisibility``, ``gaussians``, ``depth``, ``instance_ids``.
    - :class:`TaskGroup`: ``camera_centric``, ``camera_object``, ``object_centric`` (the paper's three groups).
    - :class:`AnswerType`: ``MCQ`` (letter A–D), ``YN`` ("yes"/"no"), ``NA`` (float, the question's unit), ``COUNT`` (int ≥ 0), ``SIZE_LIST`` (3 sorted floats, m).

Scene model (type hints; read-only for families)
    - :class:`Scene`: ``id``, ``views`` (name → ``Camera``), ``instances``, ``up``, ``covisibility``; metres.
    - :class:`Instance`: ``id``, ``label``, view-invariant ``description``, ``box`` (centre m, extents m, rotation columns = box axes), per-view ``visibility``.

Records
    - :class:`QARecord`: one question with its answer and ``geometry`` audit block; validated at construction (4 ``"A. text"`` options for MCQ, none otherwise).
    - :func:`make_record`: a :class:`QARecord` of a scene with its deterministic id (``key`` identifies the question within its family and views).
    - :func:`make_record_id`: ``"{scene_id}/{question_type}/{sub_question_type}/{12 hex}"``, the SHA-1 of the views and ``key``.
    - :func:`json_ready`: a value as plain JSON types (tuples/arrays → lists, numpy scalars → numbers; NaN/Inf rejected).

Geometry-block entries (JSON; world metres)
    - :func:`object_entry`: ``id``, ``label``, ``description``, box ``center`` / ``extents`` / ``rotation`` of an instance.
    - :func:`ref_entry`: ``id``, ``label``, ``description``, ``view``: an object the question names and the view it is seen in.
    - :func:`camera_entry`: view → 4×4 ``cam_to_world`` (OpenCV axes, metres).
    - :func:`pair_geometry`: ``up``, ``cam_to_world_a``, ``cam_to_world_b`` and ``pair`` of a two-view camera-motion question.
    - :func:`visibility_entry`: visible pixels, visible fraction and class of each object in each view.
    - :func:`visibility_thresholds`: the "clearly visible" thresholds, ``min_pixels`` scaled to each view's image size.
    - :func:`objects_block`: the usual head of an object question's block: ``up``, ``cameras``, ``objects``, ``refs``, ``visibility``, ``visibility_thresholds``.
    - :func:`selection_entry`: the block's ``selection`` entry: the subject (asked once per sub type and scene), the cell (what the text tells a blind model), the record's role and the cell's roles; the question index takes whole rounds of a cell's roles, so nothing the text shows predicts the answer; optional ``features`` (the labels the text names, :func:`label_features`) are balanced across the roles.
    - :func:`label_features`: the selection features of the labels a question names, by position.

Seeded order (all lazy: nothing is drawn before the first ``next``)
    - :func:`child_rngs`: ``n`` independent child generators, so skipping one candidate never shifts another's draws.
    - :func:`seeded_order`: a small list in the order of one ``rng.permutation``.
    - :func:`lazy_permutation`: ``0 … n−1`` in a uniform random order drawn lazily (huge candidate spaces).
    - :func:`round_robin`: one item from each iterator in turn until all are exhausted.
    - :func:`round_robin_views`: the scene's views in a seeded order, one record of each view's stream ``stream(scene, index, view, rng)`` in turn.
    - :func:`round_robin_pairs`: the same over the view pairs of :func:`sample_pairs` (``stream(scene, index, pair, rules, rng)``).
    - :func:`role_rounds`: whole rounds of each key's roles (``key → [candidates of role 0, role 1, …]``), keys and candidates in a seeded order: a family balanced per key, e.g. a label asked once with each answer per round.
    - :func:`round_robin_sub_types`: a family asking in one image and in two: its single-view stream and each ``(rules, stream)`` pair stream, one child generator each, one record of each sub type in turn.

Objects a question may name
    - :func:`referable`: clearly visible in the view, and no other same-label instance with the same description is seen there.
    - :func:`referable_ids`: the ids of the referable objects of a view, in id order.
    - :func:`phrase`: how a question names an instance (its description, else its label; the label is always stated).
    - :func:`phrase_key`: that phrase lower-cased and whitespace-collapsed, to test that two names differ.

Wording (English)
    - :func:`object_phrase`: ``(label, description)`` → the phrase :func:`phrase` uses.
    - :func:`find_in_image`: ``"In image A, find the red cup."`` (image index 0 → "A").
    - :func:`count_phrase`: ``"1 chair"``, ``"3 chairs"``.
    - :func:`label_text`: a label as written in text (``"coffee_table"`` → ``"coffee table"``).
    - :func:`plural`: the English plural of a label (``"shelf"`` → ``"shelves"``).
    - :func:`indefinite_article`: ``"a"`` or ``"an"`` by the first sound.
    - :func:`with_articles`: every article "a" in a text corrected to "an" before a vowel sound (``"a orange cup"`` → ``"an orange cup"``).
    - :data:`IMAGE_NAMES`: ``("A", "B", "C", "D")``: how questions name the images, in ``QARecord.views`` order.

Visibility (from rendered instance ids, computed before generation; families never render)
    - :class:`VisibilityClass`: ``VISIBLE`` (clearly), ``PARTIAL`` (grey zone: skip when certainty matters), ``HIDDEN`` (0 px).
    - :func:`classify`: the class of one instance in one view from its ``InstanceVisibility`` and the image area (px).
    - :class:`VisibilityThresholds`: ``min_pixels`` (px at 640×480, scaled with the image area) and ``min_fraction`` in (0, 1].
    - :data:`DEFAULT_THRESHOLDS`: 400 px at 640×480 and a visible fraction ≥ 0.5.
    - :data:`REFERENCE_AREA`: 640 × 480 px, the area ``min_pixels`` is stated at.
    - :class:`VisibilityIndex`: per view, ``visible`` (clearly visible ids) and ``seen`` (any visible pixel); ``instance(id)``, ``cls(view, id)``, ``vis_entry(view, id)``.

View pairs and object rules
    - :class:`PairRules`: covisibility in (``min_covisibility``, ``max_covisibility``], baseline ≥ ``min_translation_m`` m, relative rotation ≥ ``min_rotation_deg``°.
    - :class:`ViewPair`: an ordered pair (``a`` = image A, the anchor; ``b`` = image B) with its covisibility, baseline (m) and rotation (°).
    - :func:`sample_pairs`: every pair satisfying the rules, oriented by a seeded coin, round-robin over anchors (needs ``"covisibility"``).
    - :data:`TRANSLATION_PAIRS`, :data:`ROTATION_PAIRS`, :data:`OBJECT_PAIRS`, :data:`OBJECT_DIRECTION_PAIRS`, :data:`LOW_COVIS_DIRECTION_PAIRS`: the built-ins' rules (SPEC-QA "View sampling").
    - :func:`split_across_views`: the three-object rule: the two views together show all three clearly, neither shows all three.
    - :func:`description_clash`: the view shows another same-label instance with the same description (drop the question).
    - :func:`same_label_neighbours`: other instances of the same label that a view shows.
    - :func:`confusable`: two labels a person may take for one another (the label lexicon: ``"armchair"`` ⊂ ``"chair"``, ``"monitor"`` / ``"tv"``, one head noun).
    - :class:`SceneLabel`, :func:`scene_labels`: the labels a label-only question may ask about (the instances' labels and the scene vocabulary's other words, grouped by :func:`label_key`, with their spelling, source and instances).
    - :func:`label_ambiguous`: the instances a view shows that make a label-only question ambiguous (a related label, or a bookshelf for "book").
    - :class:`Lexicon`, :func:`default_lexicon`: label relations (synonyms, kinds, related pairs, objects showing unannotated ones, typical sizes), extensible by JSON (``SPACEDG_LEXICON``).
    - :func:`label_key`, :func:`description_key`, :func:`head_noun`: how labels and descriptions compare (case, spaces, ``_``).

Options (MCQ) and balance
    - :func:`build_mcq`: ``(options, letter)``: the truth and the first three distinct distractors as four ``"A. text"`` lines; the correct letter is dealt from shuffled A–D blocks of the same ``rng``, so it is uniform over a generation.
    - :class:`BalancedDeck`: ``0 … k−1`` in shuffled blocks of ``k`` (a yes/no side, or ``slot=`` of :func:`build_mcq` for per-record child generators).
    - :data:`MCQ_LETTERS`: ``("A", "B", "C", "D")``.

Cheap candidates (optional: the question index pools thousands of candidates per family and keeps a few hundred)
    - :func:`offer`: ``offer(sub, views, subject, named, selection, build)``: what ``generate`` yields for one question: the record (``build()``) normally, a light candidate inside the question index (the record is built only if the selection keeps it). Make every random draw before offering; ``selection`` and ``build`` must not draw.
    - :func:`admitted`: ``admitted(sub, views, subject, named)`` (the four values ``offer`` will get): ask once the checks that draw nothing have passed, before any draw; when ``False`` (the index has the subject's alternates or enough subjects, or a named object has a twin in the images) yield :data:`PASSED_OVER` and go on. Always ``True`` outside the index; may raise a ``BaseException`` to end the scan.
    - :data:`PASSED_OVER`: what a family yields for a candidate :func:`admitted` refused (the index counts it as examined).
    - :func:`offer_if_admitted`: ``offer_if_admitted(sub, views, subject, named, selection, build)``: the two above in one, for a candidate whose draws are all made already (drawn up front or per round): :data:`PASSED_OVER` or :func:`offer`.

Poses, directions and the ground plane
    - :func:`camera_center`: a camera's centre in world metres.
    - :func:`camera_distance`: straight-line distance from a camera's centre to a world point (an object's box centre), metres.
    - :func:`point_in_camera`: a world point in a camera's frame (OpenCV axes, metres).
    - :func:`relative_rotation`: ``R_a^T R_b``, view B's axes in view A's camera frame.
    - :func:`relative_translation`: ``R_a^T (t_b − t_a)``, B's centre in A's camera frame (metres).
    - :func:`euler_yaw_pitch_roll`: ``(yaw, pitch, roll)`` degrees of a camera-frame rotation (yaw+ = turn right, pitch+ = tilt up, roll+ = clockwise).
    - :func:`gravity_rotation`: ``(yaw, pitch, roll)`` degrees of the motion A → B as a person perceives it (heading, elevation and bank changes with gravity as reference).
    - :func:`camera_attitude`: a camera's ground heading, elevation above the horizon and bank.
    - :data:`ROTATION_WORDS`: the words of each rotation axis's positive and negative sense.
    - :func:`dominant_parts`: ``[(axis, sign), …]`` naming a direction: the largest component, plus the second when ``|c2| ≥ TAN30·|c1|``; at most ``MAX_PARTS``.
    - :func:`parts_label`: ``"right-up"`` from those parts and a word table.
    - :func:`flipped_labels`: the labels with one or both parts flipped (distractors that are never partly correct).
    - :func:`single_word_pool`: every one-word label of a word table (padding distractors).
    - :data:`CAMERA_MOTION_WORDS`, :data:`BODY_DIRECTION_WORDS`: camera-frame words per axis (x, y, z): ``(positive, negative)``.
    - :data:`TAN30`, :data:`MAX_PARTS`: 0.5774 (the 30° second-part ratio) and 2.
    - :func:`horizontal`: a vector with its component along ``up`` removed (ground-plane projection).
    - :func:`vertical_dominates`: ``|vertical| ≥ VERTICAL_FACTOR × |horizontal|`` (no reliable ground direction).
    - :func:`ground_angle`: angle on the ground plane from ``forward`` towards ``forward × up`` (clockwise seen from above), degrees in [0, 360).
    - :func:`ground_leg`: the ground-plane parts of a leg (m), or ``None`` when shorter than ``MIN_HORIZONTAL_M`` or vertical-dominant.
    - :data:`MIN_HORIZONTAL_M`, :data:`VERTICAL_FACTOR`: 0.25 m and 1.2.
    - :class:`Sectors`, :class:`SectorHit`: eight labels around the ground plane and where an angle falls (with the near-boundary neighbour).
    - :data:`RELPOS_SECTORS`, :data:`COMPASS_SECTORS`, :data:`CARDINALS`: front/…/front-left 45° sectors; compass labels by the 0.5774 rule; north/east/south/west.
    - :data:`BOUNDARY_GUARD_DEG`: 3°: within it of a sector boundary, the neighbour across is no distractor.
    - :func:`compass_frame`, :func:`compass_answer`: ground-plane (north, east) where a reference vector points to an assumed cardinal, and a query's compass label in it.
    - :func:`boxes_intersect`: two oriented boxes overlap by more than :data:`INTERSECT_TOL_M` (1 mm) along every separating axis.

Answers
    - :data:`Answer`: the type of ``QARecord.answer`` (``str | int | float | tuple[float, ...]``).
    - :func:`validate_answer`: an answer normalised for its :class:`AnswerType`, or ``InvalidDataError`` saying what a valid one is.
    - :func:`answer_text`: an answer as a model writes it inside ``<answer>…</answer>`` (size lists ``[0.31, 0.90, 1.11]``, 2 decimals).
    - :func:`answer_from_text`: a typed-in answer back to its stored text (MCQ letters upper case, yes/no lower case).
"""

from __future__ import annotations

from spacedg.plugins.answers import MCQ_LETTERS, Answer, answer_from_text, answer_text, validate_answer
from spacedg.plugins.candidates import PASSED_OVER, admitted, offer, offer_if_admitted
from spacedg.plugins.hookspecs import hookimpl
from spacedg.plugins.qa_record import QARecord, json_ready, make_record_id
from spacedg.plugins.question_family import SCENE_NEEDS, QuestionFamily
from spacedg.plugins.questions.geometry import (
    BODY_DIRECTION_WORDS,
    BOUNDARY_GUARD_DEG,
    CAMERA_MOTION_WORDS,
    CARDINALS,
    COMPASS_SECTORS,
    INTERSECT_TOL_M,
    MAX_PARTS,
    MIN_HORIZONTAL_M,
    RELPOS_SECTORS,
    ROTATION_WORDS,
    TAN30,
    VERTICAL_FACTOR,
    BalancedDeck,
    SectorHit,
    Sectors,
    boxes_intersect,
    build_mcq,
    camera_attitude,
    camera_center,
    camera_distance,
    compass_answer,
    compass_frame,
    dominant_parts,
    euler_yaw_pitch_roll,
    flipped_labels,
    gravity_rotation,
    ground_angle,
    ground_leg,
    horizontal,
    parts_label,
    point_in_camera,
    relative_rotation,
    relative_translation,
    single_word_pool,
    vertical_dominates,
)
from spacedg.plugins.questions.language import (
    IMAGE_NAMES,
    count_phrase,
    find_in_image,
    indefinite_article,
    label_text,
    object_phrase,
    plural,
    with_articles,
)
from spacedg.plugins.questions.records import (
    camera_entry,
    child_rngs,
    lazy_permutation,
    make_record,
    object_entry,
    objects_block,
    pair_geometry,
    phrase,
    phrase_key,
    ref_entry,
    referable,
    referable_ids,
    role_rounds,
    round_robin,
    round_robin_pairs,
    round_robin_sub_types,
    round_robin_views,
    seeded_order,
    selection_entry,
    label_features,
    visibility_entry,
    visibility_thresholds,
)
from spacedg.plugins.questions.view_sampling import (
    LOW_COVIS_DIRECTION_PAIRS,
    OBJECT_DIRECTION_PAIRS,
    OBJECT_PAIRS,
    ROTATION_PAIRS,
    TRANSLATION_PAIRS,
    Lexicon,
    PairRules,
    SceneLabel,
    ViewPair,
    VisibilityIndex,
    confusable,
    default_lexicon,
    label_ambiguous,
    description_clash,
    description_key,
    head_noun,
    label_key,
    same_label_neighbours,
    sample_pairs,
    scene_labels,
    split_across_views,
)
from spacedg.plugins.specs import AnswerType, TaskGroup
from spacedg.scene.model import Instance, Scene
from spacedg.scene.visibility_classes import (
    DEFAULT_THRESHOLDS,
    REFERENCE_AREA,
    VisibilityClass,
    VisibilityThresholds,
    classify,
)

__all__ = [
    # declaring and registering
    "hookimpl", "QuestionFamily", "SCENE_NEEDS", "TaskGroup", "AnswerType",
    # scene model
    "Scene", "Instance",
    # records and geometry blocks
    "QARecord", "make_record", "make_record_id", "json_ready",
    "object_entry", "ref_entry", "camera_entry", "pair_geometry", "visibility_entry", "visibility_thresholds", "objects_block",
    "selection_entry", "label_features",
    # seeded order
    "child_rngs", "seeded_order", "lazy_permutation", "role_rounds", "round_robin", "round_robin_views", "round_robin_pairs", "round_robin_sub_types",
    # objects and wording
    "referable", "referable_ids", "phrase", "phrase_key",
    "object_phrase", "find_in_image", "count_phrase", "label_text", "plural", "indefinite_article", "with_articles", "IMAGE_NAMES",
    # visibility
    "VisibilityClass", "classify", "VisibilityThresholds", "DEFAULT_THRESHOLDS", "REFERENCE_AREA", "VisibilityIndex",
    # view pairs and object rules
    "PairRules", "ViewPair", "sample_pairs",
    "TRANSLATION_PAIRS", "ROTATION_PAIRS", "OBJECT_PAIRS", "OBJECT_DIRECTION_PAIRS", "LOW_COVIS_DIRECTION_PAIRS",
    "split_across_views", "description_clash", "same_label_neighbours", "confusable", "label_key", "description_key", "head_noun",
    "label_ambiguous", "SceneLabel", "scene_labels", "Lexicon", "default_lexicon",
    # options
    "build_mcq", "BalancedDeck", "MCQ_LETTERS",
    "offer", "admitted", "offer_if_admitted", "PASSED_OVER",
    # poses, directions, ground plane
    "camera_center", "camera_distance", "point_in_camera", "relative_rotation", "relative_translation", "euler_yaw_pitch_roll", "ROTATION_WORDS",
    "gravity_rotation", "camera_attitude",
    "dominant_parts", "parts_label", "flipped_labels", "single_word_pool", "CAMERA_MOTION_WORDS", "BODY_DIRECTION_WORDS",
    "TAN30", "MAX_PARTS", "horizontal", "vertical_dominates", "ground_angle", "ground_leg", "MIN_HORIZONTAL_M", "VERTICAL_FACTOR",
    "Sectors", "SectorHit", "RELPOS_SECTORS", "COMPASS_SECTORS", "CARDINALS", "BOUNDARY_GUARD_DEG",
    "compass_frame", "compass_answer", "boxes_intersect", "INTERSECT_TOL_M",
    # answers
    "Answer", "validate_answer", "answer_text", "answer_from_text",
]
