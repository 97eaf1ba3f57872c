"""Score any agent on a track of the benchmark: `python evaluate.py track=<name> agent=<spec>`.

    python evaluate.py track=p1-exact-v1 agent=my_agent.py:act          # a NumPy function obs -> action
    python evaluate.py track=innings-v1 agent=results/policies/base/seed0.pt
    python evaluate.py track=p3-fastfiz-v1 agent=search:default          # the position-aware search
    python evaluate.py track=match-x5-v1 agent=league:safety_r
    python evaluate.py track=p1-exact-v1 agent=my_agent.py:act out=<dir>   # the same out resumes a stopped run

Writes scorecard.json and scorecard.md (and the ledger units.jsonl) into its run directory.
The app is :mod:`billiards.apps.evaluate`, the same as ``sagu evaluate`` after ``pip install sagu-bench``.
"""

from billiards.apps.evaluate import main

if __name__ == "__main__":
    main()
