"""A second example scene, written from its MuJoCo XML alone (no env code): see adapter.py."""
