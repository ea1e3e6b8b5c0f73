"""Tests of the project as a whole: import contract, sizes, docs, README, extras, packaging, public API, command-line conventions, shared data, and the test tree's own layout."""
