"""gsgeo.store"""
