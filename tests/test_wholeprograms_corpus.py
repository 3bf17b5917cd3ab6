"""The second half of the conformance corpus end to end (every other program, sorted): the
same checks as tests/test_wholeprograms.py's first half (that file's
:func:`~tests.test_wholeprograms.check_corpus_program`), in a file of its own so that the
suite's workers, one test file each, share the corpus's minutes."""

from __future__ import annotations

import pytest

from tests.test_wholeprograms import check_corpus_program, corpus_half


@pytest.mark.parametrize("rel", corpus_half(1))
def test_corpus_program_runs_end_to_end(rel):
    check_corpus_program(rel)
