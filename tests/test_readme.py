"""The README's examples are run as doctests, so the README cannot drift from the code."""
import doctest
import re
from pathlib import Path

README = Path(__file__).resolve().parent.parent / "README.md"


def test_readme_examples_run_and_print_what_the_readme_says():
    blocks = re.findall(r"```pycon\n(.*?)```", README.read_text(), flags=re.S)
    assert blocks, "the README has no ```pycon example"
    parser = doctest.DocTestParser()
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    for k, text in enumerate(blocks):
        test = parser.get_doctest(text, {}, f"README.md example {k + 1}", str(README), 0)
        runner.run(test)
    result = runner.summarize(verbose=False)
    assert result.attempted > 5 and result.failed == 0, f"{result.failed} README example line(s) failed (see above)"


def test_plan_repr_is_one_short_line():
    import numpy as np

    import stimuli
    from lgp import plan

    trial = stimuli.load_trial("9E")
    p = plan(trial.sample_initial(np.random.default_rng([0, 0])), trial.target)
    text = repr(p)
    assert "\n" not in text and len(text) < 300, text
    assert f"{len(p.actions)} actions" in text and trial.target.label.split("-")[0] in text
