"""Packaging glue: ship the top-level `schemas/` folder inside the wheel as `syncaudit.schemas`."""

from setuptools import find_packages, setup

setup(
    packages=[*find_packages("src"), "syncaudit.schemas"],
    package_dir={"": "src", "syncaudit.schemas": "schemas"},
)
