//! GPU memory manager: chunk pool, LRU/tightest-fit residency, progressive level uploads, staging and prefetch scheduling. Filled by the memory issue.
