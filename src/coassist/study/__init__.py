"""People in the loop, end to end: ``coassist study`` runs the thesis' protocols with participants.

- :mod:`coassist.study.plan`: the study plan (TOML), validated; every error names its field.
- :mod:`coassist.study.preflight`: the plan checked whole at init (its models, the session's time and memory).
- :mod:`coassist.study.ids`: pseudonymous participant ids by construction.
- :mod:`coassist.study.design`: the balanced Latin square and the blinding labels.
- :mod:`coassist.study.protocols`: comparison, iterative (Alg. 4.1), transfer (Alg. 4.2), online, as step lists.
- :mod:`coassist.study.folder`: the study folder; resumable, lossless, cross-checked as evidence; amendments.
- :mod:`coassist.study.session`: the trials on ``coassist play``'s page (blinded) or with a simulated hand.
- :mod:`coassist.study.training`: the study's models, trained in the background as ``coassist train`` does.
- :mod:`coassist.study.questionnaires`: raw NASA-TLX and Likert items.
- :mod:`coassist.study.participants`: simulated participants from the operator population.
- :mod:`coassist.study.runner`: one participant's steps, resumed where they stopped.
- :mod:`coassist.study.stats`: order effects (the paired tests, Holm and effect sizes: :mod:`coassist.analysis.paired`).
- :mod:`coassist.study.summary`: the study's summary as a typed result (:class:`~coassist.study.summary.StudySummary`).
- :mod:`coassist.study.summarise`: the summary computed from a study folder.
- :mod:`coassist.study.report`: the HTML report (rendered through the Jinja2 templates) and the JSON summary.
"""
