"""Project checks that run beside the code (import-linter contract types)."""
