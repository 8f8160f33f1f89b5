"""gsgeo.tiles"""
