"""The native flavour: C source-code FMUs generated from the same Python models (a build tool;
see docs/native.md)."""
