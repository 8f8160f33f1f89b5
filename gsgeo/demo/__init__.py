"""gsgeo.demo"""
