"""Run time: the switched observer, its cycle bookkeeping, the gain families, the innovation
consistency test, the chi-square gate."""
