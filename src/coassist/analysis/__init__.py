"""Statistics over measured results, below every experiment and study that reports them.

- :mod:`coassist.analysis.paired`: paired statistics on scipy.stats: the t interval of a paired
  difference, percentile bootstrap intervals, the share of a reference's gain, the Wilcoxon and
  paired t tests, Holm's correction and effect sizes.
"""
