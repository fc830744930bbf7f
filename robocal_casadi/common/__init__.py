"""Small shared utilities: checked YAML fields and CSV tables, declared units,
argument checks, all-or-nothing output, progress, worker processes, freed
memory, compiled CasADi batches and the one least-squares kernel."""
