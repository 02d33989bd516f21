# SPDX-License-Identifier: Apache-2.0
"""The Examples of `sweep` and `stability_map` run and print what their docstrings say
(doctest), so the documented numbers stay those of the model."""

import doctest

import pytest

from leadscrew_ros.model.studies import stability_map, sweep

DOCUMENTED = [(sweep, "sweep"), (stability_map, "stability_map")]


@pytest.mark.parametrize("module,name", DOCUMENTED, ids=[n for _, n in DOCUMENTED])
def test_examples_run_and_print_what_they_say(module, name):
    doc = getattr(module, name).__doc__
    assert "Examples\n    --------\n" in doc and ">>> " in doc, f"{name}: no Examples"
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted >= 5 and result.failed == 0, result


def test_a_wrong_example_fails():
    """The check above can fail: doctest reports a changed number."""
    finder = doctest.DocTestFinder()
    test = finder.find(
        stability_map.stability_map, "stability_map", globs=vars(stability_map).copy()
    )[0]
    example = next(e for e in test.examples if "boundary" in e.source)
    example.want = "[0.809, 55.3]\n"
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS)
    assert runner.run(test, out=lambda _: None).failed == 1
