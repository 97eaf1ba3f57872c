"""Inference-time search: `python search.py [proposer=geometric|base|gentle|near_miss|both] [search=h2|puct] [protocol=p1|p3]`.

    python search.py                                   # geometric proposer, h2, P3 on the default (paper's) table
    python search.py physics=international proposer=near_miss search=h2 protocol=p3   # a shipped ensemble, on its table
    python search.py protocol=p1 protocol.n_innings=10 protocol.shots=10              # a quick look
    python search.py resume=<run dir>                  # continue a stopped P3 from its next chain

How long: P3 on defaults plays 10 chains of up to 10,000 shots; what a decision costs at 400
simulations is measured in results/bench_search_korean_medium_1m.json (docs/search.md). The run
prints what it will do and where before it starts, and an upper bound on the time left after
its first chain. Ctrl-C keeps every finished chain (results.json marked partial).

The app is :mod:`billiards.apps.search`, the same as ``sagu search`` after ``pip install sagu-bench``.
"""

from billiards.apps.search import main

if __name__ == "__main__":
    main()
