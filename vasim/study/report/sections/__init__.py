"""The report's sections, one module each; every builder returns ``(Section, provenance rows)``
(the traceability section returns the Section only)."""
