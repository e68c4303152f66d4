"""``relay_v0``: a toy networked system that lives only in the tests, registered at run time.

It proves that a domain is one folder: nothing outside this folder names it.
"""
