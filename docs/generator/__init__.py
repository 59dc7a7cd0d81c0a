"""The documentation generator (project tooling, not part of the installed ``tsmpc`` package).

``python docs/generate.py`` runs it; the tests and ``examples/paper_explained.py`` /
``examples/paper_ablation.py`` import it with the repository's docs/ folder on ``sys.path``.

* :mod:`generator.blocks` — the marker scheme of the generated blocks of README.md and docs/*.md
  and the drift check;
* :mod:`generator.published` — the producers: every published table, number and figure from
  real runs;
* :mod:`generator.paper_explained_runs` and :mod:`generator.paper_explained` — the Table 5 study
  (the paper as it was run, and each step from there to ours): its runs, and its tables and
  figures.
"""
