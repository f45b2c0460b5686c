"""Pictures of the trials as photographs of wooden blocks on a table: Start (A) and Finish (B).

    python -m stimuli.render --out DIR [--stimuli DIR] [--seed 0] [--size 960x640] [--trials 7E 7H] [--layout pair]

For every trial it writes ``DIR/<id>-A.png`` (the layout of A that effort reports
first: sample 0 of `--seed`, drawn by ``models.effort.sample_rng(seed, 0)``; with
``--layout pair``, sample p - 1 for a trial of pair p, as the study shows) and
``DIR/<id>-B.png``, and ``DIR/renders.json`` (camera, size, seed and every
picture's inputs hash and sha256). A second run skips pictures whose inputs are
unchanged. A folder of the user's files (no renders.json), or a picture's name holding what
no render run wrote, is refused in one line (exit 2) before anything is written.

The renderer is Drake's RenderEngineVtk (VTK, OpenGL offscreen on the CPU; Drake is
already a dependency): directional lights clustered around one direction, each
casting a shadow map (their overlap gives soft penumbrae), ambient occlusion for
the contact shadows under blocks, and a wood-grain texture with darkened edges per
block colour so that touching blocks show their seams. The camera is oblique, as a
photograph taken standing at the table (28 degrees above the table, 40 degrees
round from the agent's side), and one camera serves both pictures of a trial,
framing A and B together: a tower's height shows, and a relocated tower looks
relocated. The pictures are renderings of the trial files, not the paper's
photographs (which are not public).
"""
from __future__ import annotations

import argparse

from lgp import cli
from stimuli.render.camera import DEFAULT_SIZE, parse_size
from stimuli.render.run import LAYOUTS, PROG, contact_sheet, render_trials


def main(argv=None) -> int:
    import stimuli

    parser = cli.parser(PROG, description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", required=True, type=cli.output_dir, help="folder for the PNGs and renders.json (created)")
    parser.add_argument("--stimuli", metavar="DIR", type=cli.input_dir, help="folder of trial files (default: stimuli/trials)")
    parser.add_argument("--trials", nargs="+", type=cli.trial_id, help="trial ids (default: every trial file of the folder)")
    parser.add_argument("--seed", type=cli.seed, default=0, help="A is sample 0 of this seed, as effort's (default 0)")
    parser.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, help="WIDTHxHEIGHT in pixels (default 960x640)")
    cli.add_jobs_argument(parser, 2, "rendering processes (default 2)")
    parser.add_argument("--layout", choices=LAYOUTS, default="sample0",
                        help="A of every trial is sample 0 of the seed (sample0, default: the results page's), or a trial of "
                             "pair p shows sample p - 1 (pair: the study's; a pair shares its Start, no two pairs do)")
    parser.add_argument("--sheet", metavar="PNG", type=cli.output_file, help="also write a contact sheet of all pictures")
    args = parser.parse_args(argv)
    args.jobs = cli.capped_jobs(args.jobs, parser.prog, args.oversubscribe)
    if args.trials:
        trials = [stimuli.load_trial(t, args.stimuli) for t in args.trials]
    else:
        if args.stimuli and not stimuli.trial_ids(args.stimuli):
            parser.error(f"--stimuli {args.stimuli}: no trial files (*.yaml) there")
        trials = stimuli.load_all(args.stimuli)
    record = render_trials(trials, args.out, args.seed, args.size, args.jobs, layout=args.layout)
    print(f"{len(record['pictures'])} pictures in {args.out} ({record['rendered']} rendered in {record['render_seconds']} s)")
    if args.sheet:
        print(contact_sheet(args.out, args.sheet))
    return 0


if __name__ == "__main__":
    raise SystemExit(cli.run_cli(main, prog=PROG))
