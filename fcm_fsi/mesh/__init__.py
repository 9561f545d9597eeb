"""fcm_fsi.mesh"""
