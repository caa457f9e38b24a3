"""Selection modes: a strict ``bench`` and a dense ``train`` question index.

A record's ``selection`` entry names its *subject* (:func:`~spacedg.plugins.questions.records.selection_entry`):
an object, a pair or a triplet of objects, a view pair, or a view and a label. The question
index asks each subject at most once per sub type and scene (:func:`~spacedg.qa.selection.select_records`);
what counts as "the same subject" is the mode's :func:`subject_key`:

``bench`` (strict, the default; :class:`~spacedg.qa.index.QABuildConfig` ``mode="bench"``)
    An object (or pair, or triplet) is asked **at most once per sub type and scene, whatever
    the views**: the view a family puts in front of an object subject (``"view:frame_3|object:12"``:
    camera–object distance and direction) is dropped, so the same object is not asked again
    from another view (a bench item that repeats an object rewards memorising it). Subjects
    that are a view and a label (counting, existence) or a view pair (camera motion) are kept
    as they are: another view is another question there. ``per_sub_type`` records per sub type.
``train`` (dense; ``mode="train"``, index files ``<scene id>.qa-train.jsonl``)
    Training data may ask an object from many views (the paper's training set has ~1,660
    questions per scene): the subject is the family's subject **and the record's views**, so
    only the very same question (same object, same views) is never repeated, and each sub type
    takes up to :data:`TRAIN_QUOTA_FACTOR` × ``per_sub_type`` records (:func:`quota`). Balance
    (whole rounds of every cell's roles, letters, yes/no) is the same as in the bench.

``spacedg export`` builds the bench split's indexes in ``bench`` mode and the train and val
splits' in ``train`` mode (``--qa-mode`` overrides); ``spacedg qa build --mode`` picks one;
``spacedg qa stats`` reads both where they exist.
"""

from __future__ import annotations

from collections.abc import Sequence

__all__ = ["TRAIN_QUOTA_FACTOR", "subject_key", "quota"]

#: A dense ``train`` index takes up to this many times ``per_sub_type`` records per sub type.
TRAIN_QUOTA_FACTOR = 4

#: Subject components naming objects (a view in front of them is dropped in ``bench`` mode).
_OBJECT_PARTS = ("object:", "objects:")


def subject_key(subject: str, views: Sequence[str], mode: str = "bench") -> str:
    """What "the same subject" is in ``mode`` (module docstring): ``bench`` drops a leading
    ``view:<v>|`` before an object part (``"view:f3|object:12"`` → ``"object:12"``); ``train``
    appends the record's ``views`` (``"object:12|views:f3,f7"``)."""
    if mode == "train":
        return f"{subject}|views:{','.join(views)}"
    head, sep, rest = subject.partition("|")
    if sep and head.startswith("view:") and rest.startswith(_OBJECT_PARTS):
        return rest
    return subject


def quota(per_sub_type: int, mode: str = "bench") -> int:
    """Records per sub type a scene's index takes in ``mode`` (:data:`TRAIN_QUOTA_FACTOR` × in ``train``)."""
    return per_sub_type * TRAIN_QUOTA_FACTOR if mode == "train" else per_sub_type
