"""fcm_fsi.dem"""
