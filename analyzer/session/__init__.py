"""The session core: the Session, its decoding stage and Tracker, the listener contract, the
engine choice (native core or Python), the record sequences and the offline capture run."""
