"""fcm_fsi.fcm"""
