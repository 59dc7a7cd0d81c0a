"""CLI commands of this module are added by the corresponding library layer (placeholder)."""

from __future__ import annotations
