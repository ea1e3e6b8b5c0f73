"""The test suite: one folder per package or subpackage it tests (tests/emulator/io/ tests emulator/io/), tests of the project as a whole in tests/project/."""
