"""gsgeo.export"""
