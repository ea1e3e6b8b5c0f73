"""Experiments that combine emulator, synth and scenes and write reports (markdown + png + json)."""
