"""Studies and reports over finished runs: what reads run directories, not what trains them.

* :mod:`.reproduce`: ``skillchain reproduce paper``, the paper's six runs, then its report;
* :mod:`.paper_report` and :mod:`.paper_figures`: that report's tables, claims and Figures 4-8;
* :mod:`.verify`: ``skillchain verify``, published agents re-run alone and compared bit for bit;
* :mod:`.sweep`: ``skillchain sweep``, a grid of runs and its comparison table;
* :mod:`.summary`: ``skillchain summarize``, a run's window means with standard errors;
* :mod:`.option_census`: which options of a skill-chaining run can still be chosen.

Importing the package imports none of them (the command line stays light); import the module.

Example:
    >>> from skillchain_torch.trainers.study.summary import summarize
    >>> row = summarize([[0.0, 10.0], [2.0, 30.0]], [[5, 1], [3, 1]], windows=[(1, 2)])
    >>> row["windows"][0]["return_mean"], round(row["windows"][0]["return_se"], 6)
    (10.5, 5.5)
"""
