"""gsgeo.server"""
