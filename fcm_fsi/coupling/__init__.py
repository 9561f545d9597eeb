"""fcm_fsi.coupling"""
