"""The Hydra applications, each defined once: ``train``, ``search``, ``evaluate`` and ``match``.

The repository's top-level scripts (``python train.py ...``) and the installed console command
(``sagu train ...``, :mod:`billiards.cli`) both call the ``main`` of the module named after the
app; each composes the project's ``conf/`` (:data:`billiards.files.CONF_DIR`: the checkout's own
folder, or the copy an installed package carries) and hands the config to the library.
Importing the library is deferred to inside ``main`` so that a bad command line fails within a
second.
"""

APPS = ("train", "search", "evaluate", "match")  # the modules of this package, one an app
