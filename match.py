"""Two-player Korean 4-ball: a league of players under execution noise (docs/matches.md).

    python match.py                                           # greedy vs safety-aware search vs random, fastfiz_x5
    python match.py noise=fastfiz target=30 matches=200 players=[greedy,safety]
    python match.py resume=<run dir>                          # play the league's missing matches

The app is :mod:`billiards.apps.match`, the same as ``sagu match`` after ``pip install sagu-bench``.
"""

from billiards.apps.match import main

if __name__ == "__main__":
    main()
