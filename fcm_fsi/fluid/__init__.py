"""fcm_fsi.fluid"""
