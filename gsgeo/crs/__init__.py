"""gsgeo.crs"""
