"""The evaluation harness: Table 2 of a labelled folder (`shapebag evaluate`), apart from the service.

results (options and result types) <- harness (describe, encode, rank, score) and report (table, JSON);
cache describes a folder once into an on-disk cache; sets reads the database and query folders.
"""
