"""fcm_fsi.bench"""
