"""The one header check of every PerSival file and folder (persival/file_header.py)."""

from __future__ import annotations

import pytest

from persival.file_header import check_header


class MyError(ValueError):
    pass


def test_a_header_of_this_kind_and_version_is_returned():
    header = {"format": "persival-thing", "version": 2, "x": 1}
    assert check_header(header, "a/b", "thing", "persival-thing", (1, 2)) is header


@pytest.mark.parametrize("header, message", [
    ({"format": "other", "version": 1}, r"a/b is not a thing \(format 'other', expected 'persival-thing'\)"),
    ([1, 2], r"a/b is not a thing \(format 'list'"),
    ({"format": "persival-thing", "version": 7}, r"a/b is a thing of format version 7; this PerSival reads version 1: do X"),
    ({"format": "persival-thing"}, r"format version None"),
])
def test_another_kind_or_version_is_refused_with_the_callers_error(header, message):
    with pytest.raises(MyError, match=message):
        check_header(header, "a/b", "thing", "persival-thing", 1, MyError, advice="do X")


def test_a_header_without_a_format_name_is_checked_on_its_version_key():
    assert check_header({"format_version": 3}, "s", "surrogate", None, 3, version_key="format_version")
    with pytest.raises(ValueError, match="reads version 3"):
        check_header({"format_version": 2}, "s", "surrogate", None, 3, version_key="format_version")
