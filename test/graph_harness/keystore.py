"""
An SROS2 keystore made with the openssl command (``ros2 security`` is not in the wheels).

:func:`create_keystore` writes the layout ``ros2 security create_keystore`` and
``create_enclave`` make: ``public/`` (the CA certificate as identity and permissions CA),
``private/`` (the CA key) and ``enclaves/<enclave>/`` with ``cert.pem``/``key.pem`` (an
ECDSA P-256 identity signed by the CA, subject ``CN=<enclave>``), the CA certificates and
``governance.p7s``/``permissions.p7s`` (S/MIME signed by the CA): authenticated
participants only, discovery and data encrypted, every topic allowed to the enclave on
the given domains. Used by the security test and described in docs/deployment.md.
"""
import os
import shutil
import subprocess

GOVERNANCE = """<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_governance.xsd">
  <domain_access_rules>
    <domain_rule>
      <domains><id_range><min>{low}</min><max>{high}</max></id_range></domains>
      <allow_unauthenticated_participants>false</allow_unauthenticated_participants>
      <enable_join_access_control>true</enable_join_access_control>
      <discovery_protection_kind>ENCRYPT</discovery_protection_kind>
      <liveliness_protection_kind>ENCRYPT</liveliness_protection_kind>
      <rtps_protection_kind>SIGN</rtps_protection_kind>
      <topic_access_rules>
        <topic_rule>
          <topic_expression>*</topic_expression>
          <enable_discovery_protection>true</enable_discovery_protection>
          <enable_liveliness_protection>true</enable_liveliness_protection>
          <enable_read_access_control>true</enable_read_access_control>
          <enable_write_access_control>true</enable_write_access_control>
          <metadata_protection_kind>ENCRYPT</metadata_protection_kind>
          <data_protection_kind>ENCRYPT</data_protection_kind>
        </topic_rule>
      </topic_access_rules>
    </domain_rule>
  </domain_access_rules>
</dds>
"""

PERMISSIONS = """<?xml version="1.0" encoding="UTF-8"?>
<dds xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"
     xsi:noNamespaceSchemaLocation="http://www.omg.org/spec/DDS-SECURITY/20170901/omg_shared_ca_permissions.xsd">
  <permissions>
    <grant name="{enclave}">
      <subject_name>CN={enclave}</subject_name>
      <validity><not_before>2020-01-01T00:00:00</not_before>
        <not_after>2036-01-01T00:00:00</not_after></validity>
      <allow_rule>
        <domains><id_range><min>{low}</min><max>{high}</max></id_range></domains>
        <publish><topics><topic>*</topic></topics></publish>
        <subscribe><topics><topic>*</topic></topics></subscribe>
      </allow_rule>
      <default>DENY</default>
    </grant>
  </permissions>
</dds>
"""


def _openssl(*args, cwd):
    subprocess.run(['openssl', *args], cwd=cwd, check=True, capture_output=True, timeout=60)


def _subject_config(path, common_name):
    with open(path, 'w') as handle:
        handle.write(f'[req]\ndistinguished_name = dn\nprompt = no\n[dn]\nCN = {common_name}\n')


def create_keystore(root, enclaves=('/accelcal',), domains=(0, 232)):
    """Write an SROS2 keystore under ``root`` (see the module); returns ``root``."""
    if shutil.which('openssl') is None:
        raise FileNotFoundError('the openssl command is needed to make a keystore')
    root = str(root)
    for sub in ('public', 'private', 'enclaves'):
        os.makedirs(os.path.join(root, sub), exist_ok=True)
    _subject_config(os.path.join(root, 'private', 'ca.cnf'), 'sros2_ca')
    _openssl('ecparam', '-name', 'prime256v1', '-genkey', '-noout', '-out',
             'private/ca.key.pem', cwd=root)
    _openssl('req', '-new', '-x509', '-key', 'private/ca.key.pem', '-out', 'public/ca.cert.pem',
             '-days', '3650', '-config', 'private/ca.cnf', cwd=root)
    for name in ('identity_ca', 'permissions_ca'):
        shutil.copy(os.path.join(root, 'public', 'ca.cert.pem'),
                    os.path.join(root, 'public', f'{name}.cert.pem'))
    low, high = domains
    for enclave in enclaves:
        folder = os.path.join(root, 'enclaves', enclave.strip('/'))
        os.makedirs(folder, exist_ok=True)
        _subject_config(os.path.join(folder, 'subject.cnf'), enclave)
        _openssl('ecparam', '-name', 'prime256v1', '-genkey', '-noout', '-out', 'key.pem',
                 cwd=folder)
        _openssl('req', '-new', '-key', 'key.pem', '-config', 'subject.cnf', '-out',
                 'request.csr', cwd=folder)
        ca_cert = os.path.join(root, 'public', 'ca.cert.pem')
        ca_key = os.path.join(root, 'private', 'ca.key.pem')
        _openssl('x509', '-req', '-in', 'request.csr', '-CA', ca_cert, '-CAkey', ca_key,
                 '-CAcreateserial', '-CAserial', os.path.join(root, 'private', 'ca.srl'),
                 '-days', '3650', '-out', 'cert.pem', cwd=folder)
        for name in ('identity_ca', 'permissions_ca'):
            shutil.copy(ca_cert, os.path.join(folder, f'{name}.cert.pem'))
        for name, text in (('governance', GOVERNANCE), ('permissions', PERMISSIONS)):
            with open(os.path.join(folder, f'{name}.xml'), 'w') as handle:
                handle.write(text.format(low=low, high=high, enclave=enclave))
            _openssl('smime', '-sign', '-text', '-in', f'{name}.xml', '-out', f'{name}.p7s',
                     '-signer', ca_cert, '-inkey', ca_key, cwd=folder)
    return root
